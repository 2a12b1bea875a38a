"""`App`: the optional base class of an app.

An app is any class with `run(self, bot, stop_event)`, plain or `async def`;
the runner makes one instance (no arguments), connects a `Bot` named after
the app, and calls `run` until it returns or `stop_event` is set (then it has
a grace time to return). Deriving from `App` only adds a `name`.
"""

from __future__ import annotations

import threading
from collections.abc import Awaitable

from buddybot.sdk import Bot


class App:
    """Base class of an app (optional: any class with `run(bot, stop_event)` is one)."""

    name: str | None = None
    """The app's node name (`buddybot nodes`, lease holder); None: from how it was
    given (the file's stem, the module's last part, the installed name)."""

    def run(self, bot: Bot, stop_event: threading.Event) -> Awaitable[None] | None:
        """The app's work, until `stop_event` is set (sync), or cancelled (async)."""
        raise NotImplementedError(f"{type(self).__name__} does not define run(bot, stop_event)")
