"""Derived events from who is present (pure): dwell from the real arrival, a
distance line with hysteresis, approach and leave from the distance trend."""

from __future__ import annotations

import math

import pytest

from buddybot.sdk.persons import Person
from buddybot.sdk.triggers import Dwell, Motion, Within

S = 1_000_000_000


def person(pid: int = 1, distance: float | None = 1.0, arrived_s: float = 0.0) -> Person:
    return Person(id=pid, zone="PERSONAL", engagement="NONE", distance_m=distance,
                  arrived_ns=round(arrived_s * S))


def kinds(events: list) -> list[tuple[str, int]]:
    return [(e.kind, e.person.id) for e in events]


def test_dwell_comes_once_per_person_at_their_arrival_plus_the_time() -> None:
    dwell = Dwell(10.0)
    assert dwell.update(5 * S, (person(1, arrived_s=0.0),)) == []
    [event] = dwell.update(12 * S, (person(1, arrived_s=0.0), person(2, arrived_s=9.0)))
    assert (event.kind, event.person.id, event.stamp_ns) == ("DWELL", 1, 10 * S)
    assert dwell.update(13 * S, (person(1), person(2, arrived_s=9.0))) == []
    assert kinds(dwell.update(19 * S, (person(2, arrived_s=9.0),))) == [("DWELL", 2)]
    # Gone and back as a new visit (a new id): a new dwell.
    assert kinds(dwell.update(40 * S, (person(3, arrived_s=20.0),))) == [("DWELL", 3)]


def test_someone_already_there_counts_from_their_arrival_not_from_now() -> None:
    assert kinds(Dwell(10.0).update(100 * S, (person(1, arrived_s=50.0),))) == [("DWELL", 1)]


def test_a_distance_line_has_hysteresis() -> None:
    within = Within(1.0, margin_m=0.2)
    out = []
    for t, d in enumerate([2.0, 1.0, 1.1, 0.9, 1.15, 1.19, 1.21, 1.1, 0.95]):
        out += kinds(within.update(t * S, (person(1, d),)))
    assert out == [("NEAR", 1), ("FAR", 1), ("NEAR", 1)]


def test_a_person_without_a_distance_is_neither_near_nor_far() -> None:
    assert Within(1.0).update(0, (person(1, None),)) == []


def walk(motion: Motion, distances: list[float], period_s: float = 0.1,
         start_s: float = 0.0) -> list[tuple[str, int]]:
    out = []
    for i, d in enumerate(distances):
        out += kinds(motion.update(round((start_s + i * period_s) * S), (person(1, d),)))
    return out


def test_walking_up_then_standing_then_walking_away() -> None:
    motion = Motion(speed_mps=0.3, window_s=1.0)
    up = [3.0 - 0.1 * i for i in range(20)]  # 1 m/s towards the robot
    still = [1.1 + 0.01 * math.sin(i) for i in range(30)]  # a sway
    away = [1.1 + 0.08 * i for i in range(20)]  # 0.8 m/s away
    assert walk(motion, up + still + away) == [("APPROACHING", 1), ("RECEDING", 1)]


def test_a_sway_is_no_motion() -> None:
    assert walk(Motion(), [1.0 + 0.05 * math.sin(i / 2) for i in range(100)]) == []


@pytest.mark.parametrize(("make", "bad"), [
    (lambda: Dwell(-1.0), "seconds"), (lambda: Within(0.0), "metres"),
    (lambda: Within(1.0, math.nan), "margin_m"), (lambda: Motion(0.0), "speed_mps")])
def test_nonsense_is_refused(make, bad: str) -> None:
    with pytest.raises(ValueError, match=bad):
        make()
