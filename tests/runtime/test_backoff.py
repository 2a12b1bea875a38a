"""The one retry rule (runtime/backoff.py): pure, so every number is checked here."""

from __future__ import annotations

from buddybot.runtime.backoff import Backoff


def test_doubles_from_initial_up_to_the_cap() -> None:
    b = Backoff(1.0, 30.0)
    assert [b.next() for _ in range(8)] == [1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0, 30.0]


def test_reset_starts_the_series_again() -> None:
    b = Backoff(0.5, 5.0)
    assert [b.next() for _ in range(3)] == [0.5, 1.0, 2.0]
    b.reset()
    assert b.next() == 0.5


def test_delay_peeks_without_advancing() -> None:
    """The radar bridge waits `delay` after a lost link without growing it."""
    b = Backoff(0.5, 5.0)
    b.next()
    assert b.delay == b.delay == 1.0
    assert b.next() == 1.0
    assert b.delay == 2.0


def test_factor_is_used() -> None:
    b = Backoff(1.0, 100.0, factor=3.0)
    assert [b.next() for _ in range(5)] == [1.0, 3.0, 9.0, 27.0, 81.0]


def test_a_stable_run_resets_only_from_stable_s_on() -> None:
    b = Backoff(1.0, 30.0, stable_s=30.0)
    assert [b.after_run(2.0) for _ in range(4)] == [1.0, 2.0, 4.0, 8.0]
    assert b.after_run(29.9) == 16.0
    assert b.after_run(30.0) == 1.0
    assert b.after_run(0.1) == 2.0


def test_without_stable_s_a_long_run_does_not_reset() -> None:
    b = Backoff(1.0, 30.0)
    b.next()
    assert b.after_run(1e9) == 2.0


def test_a_long_outage_stays_at_the_cap() -> None:
    """A camera unplugged for days: no overflow, no growth past the cap."""
    b = Backoff(0.5, 10.0)
    delays = [b.next() for _ in range(5000)]
    assert delays[-1] == 10.0 and max(delays) == 10.0
    b.reset()
    assert b.next() == 0.5
