"""The runner's promises, without processes: a stop ends `run` (sync: the event, async:
cancellation), an exception is exit 1 with its traceback logged, a `run` that ignores
the stop is left behind after the grace time."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from typing import Any

import pytest

from buddybot.apps.runner import Outcome, run_app
from buddybot.runtime.errors import EXIT_FAILURE, EXIT_OK

BOT: Any = object()  # the runner hands the bot over and never touches it


def stop_soon(stop: threading.Event, after_s: float = 0.2) -> None:
    threading.Timer(after_s, stop.set).start()


class Returns:
    def run(self, bot: Any, stop_event: threading.Event) -> None:
        assert bot is BOT


class Waits:
    def run(self, bot: Any, stop_event: threading.Event) -> None:
        stop_event.wait()


class Raises:
    def run(self, bot: Any, stop_event: threading.Event) -> None:
        raise RuntimeError("the app's bug")


class Ignores:
    def run(self, bot: Any, stop_event: threading.Event) -> None:
        while True:
            time.sleep(0.05)


class AsyncForever:
    cancelled = False

    async def run(self, bot: Any, stop_event: threading.Event) -> None:
        try:
            await asyncio.sleep(3600)
        except asyncio.CancelledError:
            AsyncForever.cancelled = True
            raise


class AsyncRaises:
    async def run(self, bot: Any, stop_event: threading.Event) -> None:
        await asyncio.sleep(0)
        raise ValueError("async bug")


class AsyncSwallows:
    async def run(self, bot: Any, stop_event: threading.Event) -> None:
        while True:
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.sleep(3600)


def test_a_run_that_returns_is_a_success() -> None:
    assert run_app(Returns(), BOT, threading.Event()) == Outcome(EXIT_OK)


def test_a_stop_ends_a_sync_run_that_waits_for_it() -> None:
    stop = threading.Event()
    stop_soon(stop)
    start = time.monotonic()
    assert run_app(Waits(), BOT, stop, grace_s=5.0) == Outcome(EXIT_OK)
    assert time.monotonic() - start < 2.0


def test_an_exception_is_exit_one_with_its_traceback_logged(
        caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.ERROR, "buddybot.app"):
        assert run_app(Raises(), BOT, threading.Event()) == Outcome(EXIT_FAILURE)
        assert run_app(AsyncRaises(), BOT, threading.Event()) == Outcome(EXIT_FAILURE)
    texts = [r.getMessage() + (r.exc_text or "") for r in caplog.records]
    assert any("Raises.run raised" in t for t in texts)
    tracebacks = [r.exc_info for r in caplog.records if r.exc_info]
    assert [type(e[1]).__name__ for e in tracebacks] == ["RuntimeError", "ValueError"]


def test_a_run_that_ignores_the_stop_is_left_after_the_grace_time() -> None:
    stop = threading.Event()
    stop_soon(stop)
    start = time.monotonic()
    assert run_app(Ignores(), BOT, stop, grace_s=0.3) == Outcome(EXIT_OK, hung=True)
    assert 0.4 < time.monotonic() - start < 3.0


def test_an_async_run_is_cancelled_by_the_stop() -> None:
    stop = threading.Event()
    stop_soon(stop)
    assert run_app(AsyncForever(), BOT, stop, grace_s=5.0) == Outcome(EXIT_OK)
    assert AsyncForever.cancelled


def test_an_async_run_that_swallows_the_cancellation_is_left_after_the_grace_time() -> None:
    stop = threading.Event()
    stop_soon(stop)
    assert run_app(AsyncSwallows(), BOT, stop, grace_s=0.3).hung
