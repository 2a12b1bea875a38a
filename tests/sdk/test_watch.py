"""`Watchers`: the callbacks behind every `on_...` of the SDK (pure)."""

from __future__ import annotations

import logging

import pytest

from buddybot.sdk.watch import Watchers


def test_a_late_callback_gets_the_newest_value_then_the_next_ones() -> None:
    news: Watchers[int] = Watchers("test")
    early: list[int] = []
    news.add(early.append)
    news.notify(1)
    news.notify(2)
    late: list[int] = []
    news.add(late.append)
    news.notify(3)
    assert (early, late) == ([1, 2, 3], [2, 3])


def test_before_any_value_nothing_is_replayed() -> None:
    news: Watchers[str] = Watchers("test")
    got: list[str] = []
    news.add(got.append)
    assert got == []


def test_a_closed_watch_hears_nothing_more_and_closing_twice_is_harmless() -> None:
    news: Watchers[int] = Watchers("test")
    got: list[int] = []
    with news.add(got.append) as watch:
        news.notify(1)
    news.notify(2)
    watch.close()
    assert got == [1] and watch.closed


def test_a_failing_callback_is_logged_and_the_others_still_hear(
        caplog: pytest.LogCaptureFixture) -> None:
    news: Watchers[int] = Watchers("lease")

    def broken(_value: int) -> None:
        raise RuntimeError("boom")

    got: list[int] = []
    news.add(broken)
    news.add(got.append)
    with caplog.at_level(logging.ERROR, "buddybot.sdk"):
        news.notify(7)
    assert got == [7]
    assert "lease callback" in caplog.text and "boom" in caplog.text


def test_clear_drops_every_callback() -> None:
    news: Watchers[int] = Watchers("test")
    got: list[int] = []
    news.add(got.append)
    news.clear()
    news.notify(1)
    assert got == []
