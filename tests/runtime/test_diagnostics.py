"""Diagnostics and RateLimitedLog, without a bus: a recording publisher stands in."""

from __future__ import annotations

import logging
from typing import Any

import pytest

from buddybot.contract import messages as m
from buddybot.runtime import diagnostics, limits
from buddybot.runtime.diagnostics import Diagnostics, RateLimitedLog


class Recorder:
    """Takes what `Diagnostics` puts, as a publisher would."""

    def __init__(self) -> None:
        self.sent: list[m.DiagnosticStatus] = []

    def put(self, msg: m.DiagnosticStatus) -> None:
        self.sent.append(msg)


def make(dropped: list[tuple[str, int]] | None = None) -> tuple[Diagnostics, Recorder]:
    pub = Recorder()
    diag = Diagnostics("unit", 2.0, pub, lambda: dropped or [])  # type: ignore[arg-type]
    return diag, pub


def test_a_status_change_publishes_at_once_and_a_repeat_does_not() -> None:
    diag, pub = make()
    diag.set("WARN", "camera silent")
    diag.set("WARN", "camera silent")
    assert [(s.level, s.message) for s in pub.sent] == [("WARN", "camera silent")]
    diag.set("OK", "running")
    assert [s.level for s in pub.sent] == ["WARN", "OK"]
    assert all(s.node == "unit" for s in pub.sent)


def test_counters_and_dropped_samples_are_in_the_values() -> None:
    diag, pub = make(dropped=[("radar/0/frames", 3), ("faces", 0)])
    diag.increment("frames")
    diag.increment("frames", 4)
    diag.publish()
    assert pub.sent[-1].values == {"frames": 5, "dropped radar/0/frames": 3}


def test_a_long_message_is_clipped() -> None:
    diag, pub = make()
    diag.set("ERROR", "x" * 10_000)
    assert len(pub.sent[0].message) <= limits.LOG_TEXT_MAX + 20


def test_without_a_publisher_counters_are_kept_and_nothing_is_sent() -> None:
    diag = Diagnostics("probe", 2.0, None, lambda: [])
    diag.increment("n")
    diag.set("WARN", "x")
    diag.publish()
    assert diag.values == {"n": 1} and diag.level == "WARN"


def test_rate_limited_log_reports_the_first_then_a_summary(
        caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    now = [100.0]
    monkeypatch.setattr(diagnostics.time, "monotonic", lambda: now[0])
    log = RateLimitedLog(logging.getLogger("test.ratelimited"), period_s=5.0)
    args: Any = ("k",)
    with caplog.at_level(logging.WARNING, "test.ratelimited"):
        for _ in range(4):
            log.warning("bad", "bad sample on %s", *args)
        log.warning("other", "other topic")
        now[0] += 5.0
        log.warning("bad", "bad sample on %s", *args)
    assert [r.getMessage() for r in caplog.records] == [
        "bad sample on k", "other topic", "bad sample on k (+3 more since last report)"]
