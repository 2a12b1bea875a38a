"""`buddybot.apps`: apps, programs that share the robot with its built-in behaviour.

An app is a class with `run(self, bot, stop_event)` (sync or `async def`),
optionally derived from `App` for its `name`. `loading` finds the class from
a file, a module or an installed name (entry-point group `buddybot.apps`),
`runner` runs it under `buddybot app run` and `up`'s `[apps]`, `template`
is what `buddybot app new` writes. docs/apps.md is the tutorial.
"""

from buddybot.apps.app import App
from buddybot.apps.loading import GROUP, AppError, LoadedApp, installed_apps, load_app

__all__ = ["GROUP", "App", "AppError", "LoadedApp", "installed_apps", "load_app"]
