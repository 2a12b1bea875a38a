"""The one rate module (runtime/rates.py): fixed-window counts and first-to-last spans."""

from __future__ import annotations

import math
from collections import deque

import pytest

from buddybot.runtime.rates import RateCounter, TokenBucket, count_hz, rate_hz, span_hz


def test_rate_counts_only_the_window() -> None:
    arrivals = deque([0.0, 7.1, 7.5, 8.0, 9.0, 9.9])
    assert rate_hz(arrivals, now=10.0, window_s=3.0) == 5 / 3.0
    assert rate_hz([7.0, 9.0], now=10.0, window_s=3.0) == 2 / 3.0  # the edge counts


def test_rate_drops_to_zero_when_the_sender_stops() -> None:
    assert rate_hz([1.0, 1.1, 1.2], now=10.0, window_s=3.0) == 0.0
    assert rate_hz([], now=10.0) == 0.0


@pytest.mark.parametrize(("count", "window_s", "hz"), [
    (30, 3.0, 10.0),
    (0, 3.0, 0.0),
    (5, 0.0, 0.0),
    (5, -1.0, 0.0),
    (1, 0.5, 2.0),
])
def test_count_over_a_window(count: int, window_s: float, hz: float) -> None:
    assert count_hz(count, window_s) == hz


def test_span_is_one_over_the_mean_gap() -> None:
    assert span_hz([]) is None and span_hz([5.0]) is None
    assert span_hz([0.0, 0.1, 0.2, 0.3, 0.4]) == pytest.approx(10.0)
    assert span_hz([1.0, 1.5, 3.0]) == pytest.approx(1.0)


def test_span_of_equal_stamps_is_infinite_not_an_error() -> None:
    assert math.isinf(span_hz([2.0, 2.0]) or 0.0)


def test_counter_forgets_arrivals_older_than_the_window() -> None:
    c = RateCounter(window_s=2.0)
    assert c.add(0.0) is None
    for i in range(1, 31):  # 30 fps for one second
        rate = c.add(i / 30)
    assert rate == pytest.approx(30.0)
    for i in range(1, 11):  # then 10 fps for three seconds
        rate = c.add(1.0 + i * 0.3)
    assert rate == pytest.approx(1 / 0.3)
    assert all(4.0 - t <= 2.0 for t in c.stamps)


def test_a_token_bucket_allows_the_burst_then_the_rate_and_never_waits() -> None:
    bucket = TokenBucket(rate_per_s=10.0, burst=3.0, now=100.0)
    assert [bucket.take(100.0) for _ in range(4)] == [True, True, True, False]
    assert not bucket.take(100.05)  # half a token back
    assert bucket.take(100.1) and not bucket.take(100.1)
    assert [bucket.take(200.0) for _ in range(4)] == [True, True, True, False]  # capped
    assert not bucket.take(150.0)  # a clock going back refills nothing


def test_a_token_bucket_on_a_wall_clock_in_seconds_refills_exactly_one_token() -> None:
    now = 1.7e9 + 0.123456789
    bucket = TokenBucket(rate_per_s=20.0, burst=1.0, now=now)
    assert bucket.take(now) and not bucket.take(now)
    assert bucket.take(now + 1 / 20)  # float rounding must not lose the token


def test_a_token_bucket_follows_a_changed_rate() -> None:
    bucket = TokenBucket(rate_per_s=1.0, burst=1.0, now=0.0)
    assert bucket.take(0.0) and not bucket.take(0.5)
    bucket.rate_per_s = 100.0
    assert bucket.take(0.51)
