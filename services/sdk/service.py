"""Run a program written on the SDK as one of the robot's services.

The robot's own behaviour is an app like any other (`run(bot, stop_event)`);
what makes it a service is how it starts: `buddybot run <name>` waits for
the router instead of giving up, tells systemd it is ready, stops on
SIGTERM, reads the program's own config section with command-line
overrides on top, and gives it the one `Bot` with `builtin` rights (wishes
on the eyes, no "audio" lease). Everything it needs from the runtime comes
through here, so its own code imports the SDK and nothing below it.
"""

from __future__ import annotations

import threading
from typing import Protocol, TypeVar

import msgspec

from buddybot.runtime.diagnostics import RateLimitedLog
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.service import ServiceContext
from buddybot.sdk.actions import MAX_ACTIONS_PER_S
from buddybot.sdk.bot import Bot

S = TypeVar("S", bound=msgspec.Struct)


class Runnable(Protocol):
    def run(self, bot: Bot, stop_event: threading.Event) -> None: ...


def settings_of(ctx: ServiceContext, struct: type[S]) -> S:
    """The program's config section `struct` with the command line's options on top."""
    return merge(ctx.config.section(struct), ctx.args)


def run_builtin(ctx: ServiceContext, app: Runnable) -> int:
    """Connect the service's node (waiting for the router), run `app` with the
    built-in `Bot` until the service is stopped, always close; exit status 0."""
    bot = Bot(ctx.node(), builtin=True, actions_per_s=MAX_ACTIONS_PER_S,
              actions_burst=MAX_ACTIONS_PER_S)
    try:
        app.run(bot, ctx.stop)
    finally:
        bot.close()
    return 0


__all__ = ["ConfigError", "RateLimitedLog", "Runnable", "ServiceContext", "run_builtin",
           "settings_of", "settings_option"]
