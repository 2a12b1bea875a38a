"""Run one app: load it, connect its `Bot`, call `run(bot, stop_event)`, always close.

The app runs on a worker thread (an `async def run` in its own event loop
there), so the main thread keeps the promises an app cannot break:

* SIGTERM/SIGINT set `stop_event` (an async `run` is also cancelled); if
  `run` has not returned `grace_s` after that, the process exits anyway;
* an exception escaping `run` is logged with its traceback: exit 1 (`up`
  restarts it with backoff);
* a bad app or usage is exit 2 (`AppError`, raised before connecting):
  `up` does not restart it;
* `bot.close()` always runs, so its leases are released; a process killed
  outright loses its liveliness token and its leases end with it.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import os
import sys
import threading
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import Any

from buddybot.apps.loading import AppError, load_app
from buddybot.runtime.errors import EXIT_FAILURE, EXIT_OK
from buddybot.runtime.service import ServiceContext
from buddybot.sdk import Bot

GRACE_S = 3.0
"""How long `run` has to return once stopped, before the process exits anyway."""
_POLL_S = 0.05

log = logging.getLogger("buddybot.app")


@dataclass(frozen=True)
class Outcome:
    status: int
    """EXIT_OK (returned, or stopped) or EXIT_FAILURE (raised)."""
    hung: bool = False
    """`run` had not returned `grace_s` after the stop: the process must exit anyway."""


def run_app(app: Any, bot: Bot, stop: threading.Event, grace_s: float = GRACE_S) -> Outcome:
    """Call `app.run(bot, stop)` on a worker thread until it returns, or until
    `grace_s` after `stop` is set."""
    done = threading.Event()
    failed: list[BaseException] = []

    def work() -> None:
        try:
            result = app.run(bot, stop)
            if inspect.isawaitable(result):
                asyncio.run(_until_stopped(result, stop))
        except BaseException as exc:  # the app's bug: reported, not the runner's death
            failed.append(exc)
            log.error("%s.run raised", type(app).__name__, exc_info=exc)
        finally:
            done.set()

    worker = threading.Thread(target=work, name="app", daemon=True)
    worker.start()
    while not done.wait(_POLL_S):
        if stop.is_set():
            if not done.wait(grace_s):
                log.error("%s.run did not return within %g s of the stop; exiting anyway",
                          type(app).__name__, grace_s)
                return Outcome(EXIT_OK, hung=True)
            break
    if failed:
        return Outcome(EXIT_FAILURE)
    if not stop.is_set():
        log.info("%s.run returned", type(app).__name__)
    return Outcome(EXIT_OK)


async def _until_stopped(awaitable: Awaitable[Any], stop: threading.Event) -> None:
    """Await the app's coroutine; cancel it when `stop` is set (a clean stop)."""
    task = asyncio.ensure_future(awaitable)
    while not task.done():
        if stop.is_set():
            task.cancel()
            break
        await asyncio.wait({task}, timeout=_POLL_S)
    try:
        await task
    except asyncio.CancelledError:
        if not stop.is_set():
            raise


def main(ctx: ServiceContext, spec: str, name: str | None = None,
         grace_s: float = GRACE_S) -> int:
    """`buddybot app run SPEC`: load, connect as the app's name, run, close."""
    loaded = load_app(spec)
    try:
        app = loaded.cls()
    except Exception:
        log.exception("%s() raised", loaded.cls.__name__)
        return EXIT_FAILURE
    node = name or loaded.name
    if ctx.stop.is_set():
        return EXIT_OK
    bot = Bot.from_args(ctx.args, name=node)
    log.info("app %s (%s) running on robot %s", node, loaded.spec, bot.robot)
    outcome = Outcome(EXIT_FAILURE, hung=True)
    try:
        outcome = run_app(app, bot, ctx.stop, grace_s)
    finally:
        try:
            bot.close()
        finally:
            if outcome.hung:  # the worker is stuck in the app's code: do not wait for it
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(outcome.status)
    return outcome.status


__all__ = ["GRACE_S", "AppError", "Outcome", "main", "run_app"]
