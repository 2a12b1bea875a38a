"""The angle-radar tracker: ids across slot swaps, jitter, crossings, several
sensors, the coast time and the bound, with examples and hypothesis properties.

Limits the properties state (and the tracker's docstring explains): two
people are kept apart when, at every report, each is nearer its own
predicted position than the other's; the crossings generated here pass at
least 0.5 m apart at walking speeds (0.3-1.5 m/s), as two people walking
past each other do. Closer, the sensor itself merges them into one target.
"""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from buddybot.people.tracker import Report, Target, Tracker, TrackerLimits
from tests.properties import examples

REPORT = 100_000_000  # ns: the LD2450 reports 10 times a second
A = (1, 0)
B = (1, 1)


def report(i: int, *points: tuple[float, float], sensor: tuple[int, int] = A) -> Report:
    return Report(i * REPORT, sensor, tuple(Target(x, y) for x, y in points))


def ids_at(tracker: Tracker) -> dict[int, tuple[float, float]]:
    return {t.id: (t.x_m, t.y_m) for t in tracker.tracks()}


def nearest_id(tracker: Tracker, point: tuple[float, float]) -> int:
    return min(tracker.tracks(), key=lambda t: math.dist((t.x_m, t.y_m), point)).id


def test_one_target_keeps_its_id_while_it_walks() -> None:
    tracker = Tracker()
    for i in range(30):
        tracker.update(report(i, (2.0, -1.5 + i * 0.1)))
    (track,) = tracker.tracks()
    assert track.id == 1
    assert track.bearing_rad == pytest.approx(math.atan2(1.4, 2.0))
    assert track.distance_m == pytest.approx(math.hypot(2.0, 1.4))
    assert track.sensors == frozenset({A})


def test_a_slot_swap_keeps_the_ids() -> None:
    tracker = Tracker()
    tracker.update(report(0, (1.0, 1.0), (3.0, -1.0)))
    first = ids_at(tracker)
    tracker.update(report(1, (3.0, -1.0), (1.0, 1.0)))
    assert ids_at(tracker) == first


def test_a_target_beyond_the_gate_is_a_new_track() -> None:
    tracker = Tracker(TrackerLimits(gate_m=0.5))
    tracker.update(report(0, (1.0, 0.0)))
    tracker.update(report(1, (2.0, 0.0)))
    assert sorted(ids_at(tracker)) == [1, 2]


def test_a_track_coasts_then_is_dropped() -> None:
    tracker = Tracker(TrackerLimits(coast_s=1.0))
    tracker.update(report(0, (1.0, 0.0)))
    for i in range(1, 10):  # missed reports: still there
        tracker.update(report(i))
    assert tracker.next_deadline() == 1_000_000_000
    assert tracker.expire(999_999_999) == []
    assert tracker.expire(1_000_000_000) == [1]
    assert tracker.tracks() == ()
    tracker.update(report(11, (1.0, 0.0)))
    assert [t.id for t in tracker.tracks()] == [2]  # ids are never reused


def test_two_sensors_at_one_place_make_one_track() -> None:
    tracker = Tracker()
    for i in range(10):
        tracker.update(report(i, (2.0, 0.5 + 0.05 * i)))
        tracker.update(Report(i * REPORT + 50_000_000, B, (Target(2.08, 0.46 + 0.05 * i),)))
    (track,) = tracker.tracks()
    assert track.sensors == frozenset({A, B})


def test_a_person_passing_from_one_sensor_to_the_other_keeps_the_id() -> None:
    tracker = Tracker()
    for i in range(40):  # A sees y > -0.2, B sees y < 0.2 (overlap in the middle)
        y = 2.0 - i * 0.1
        if y > -0.2:
            tracker.update(report(i, (1.5, y)))
        if y < 0.2:
            tracker.update(Report(i * REPORT + 1, B, (Target(1.5, y),)))
        tracker.expire(i * REPORT + 1)
    (track,) = tracker.tracks()
    assert track.id == 1


def test_at_most_max_tracks() -> None:
    tracker = Tracker(TrackerLimits(max_tracks=2))
    tracker.update(report(0, (1.0, 0.0), (2.0, 0.0), (3.0, 0.0)))
    assert len(tracker.tracks()) == 2
    assert tracker.refused == 1


@pytest.mark.parametrize("near, far", [(2.0, 2.5), (2.5, 2.0)])
def test_two_people_crossing_keep_their_ids(near: float, far: float) -> None:
    tracker = Tracker()
    tracker.update(report(0, (far, 2.0)))  # the other one is seen first
    tracker.update(report(0, (near, -2.0), (far, 2.0)))
    walker = nearest_id(tracker, (near, -2.0))
    for i in range(1, 41):  # one walks to the left, the other to the right, 0.5 m apart
        tracker.update(report(i, (near, -2.0 + 0.1 * i), (far, 2.0 - 0.1 * i)))
    assert nearest_id(tracker, (near, 2.0)) == walker


# --- properties --------------------------------------------------------------------------

coordinate = st.floats(-4.0, 4.0, allow_nan=False)
point = st.tuples(st.floats(0.2, 6.0, allow_nan=False), coordinate)


@given(st.lists(st.lists(point, min_size=0, max_size=3), min_size=1, max_size=15),
       st.randoms(use_true_random=False))
def test_slot_permutations_never_change_ids(reports: list[list[tuple[float, float]]],
                                            rnd: random.Random) -> None:
    ordered, shuffled = Tracker(), Tracker()
    for i, points in enumerate(reports):
        mixed = list(points)
        rnd.shuffle(mixed)
        assert ordered.update(report(i, *points)) == shuffled.update(report(i, *mixed))
        assert ordered.tracks() == shuffled.tracks()


@given(point, st.lists(st.tuples(st.floats(-0.15, 0.15), st.floats(-0.15, 0.15)),
                       min_size=1, max_size=60))
def test_a_target_jittering_within_the_gate_keeps_its_id(
        start: tuple[float, float], jitter: list[tuple[float, float]]) -> None:
    # Jitter of up to +-0.15 m per axis: two readings are at most 0.6 m apart, the gate.
    tracker = Tracker(TrackerLimits(gate_m=0.6))
    tracker.update(report(0, start))
    for i, (dx, dy) in enumerate(jitter, start=1):
        tracker.update(report(i, (start[0] + dx, start[1] + dy)))
        assert [t.id for t in tracker.tracks()] == [1]


@settings(max_examples=examples(200))
@given(st.floats(1.0, 4.0), st.floats(0.5, 2.0), st.floats(0.3, 1.5), st.floats(0.3, 1.5),
       st.floats(-0.5, 0.5), st.lists(st.tuples(st.floats(-0.05, 0.05),
                                                st.floats(-0.05, 0.05)), min_size=80,
                                      max_size=80), st.booleans())
@example(2.0, 0.5, 1.0, 1.0, 0.0, [(0.0, 0.0)] * 80, False)
def test_two_people_crossing_keep_distinct_ids(
        x: float, apart: float, speed1: float, speed2: float, offset: float,
        noise: list[tuple[float, float]], nearer_first: bool) -> None:
    """Walking past each other in opposite directions, `apart` metres apart in depth
    (>= 0.5 m), each at its own speed, with 5 cm of jitter: ids never swap."""
    tracker = Tracker()
    x1, x2 = (x, x + apart) if nearer_first else (x + apart, x)
    for i in range(80):
        t = i / 10
        p1 = (x1 + noise[i][0], -3.0 + speed1 * t + noise[i][1])
        p2 = (x2 - noise[i][0], 3.0 + offset - speed2 * t - noise[i][1])
        tracker.update(report(i, p1, p2))
        if i == 0:
            first, second = nearest_id(tracker, p1), nearest_id(tracker, p2)
        assert len(tracker.tracks()) == 2
        assert (nearest_id(tracker, p1), nearest_id(tracker, p2)) == (first, second)


def test_non_finite_targets_are_refused() -> None:
    with pytest.raises(ValueError):
        Target(math.nan, 0.0)
