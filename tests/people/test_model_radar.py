"""The people model with angle radars: tracks become persons, the face joins the
person at its bearing, several persons at once, scenario by scenario.

Settings as in test_model.py (absence hold 3 s, face timeout 0.5 s) and the
tracker's defaults (gate 0.6 m, coast 1 s); a report every 0.1 s.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from buddybot.people.model import FaceSeen, Input, PeopleModel, RadarSeen, Sensor, TargetsSeen
from buddybot.people.tracker import Target

from .test_model import SETTINGS, ns, row, run, tick

SENSOR = (1, 0)


def targets(t: float, *points: tuple[float, float], sensor: tuple[int, int] = SENSOR
            ) -> TargetsSeen:
    return TargetsSeen(ns(t), sensor, tuple(Target(x, y) for x, y in points))


def walk(start: float, end: float, path: list[tuple[float, float, float, float]]
         ) -> Iterator[TargetsSeen]:
    """Reports every 0.1 s; each path entry is a person (x, y at `start`, vx, vy)."""
    for i in range(round((end - start) * 10) + 1):
        dt = i / 10
        yield targets(start + dt, *((x + vx * dt, y + vy * dt) for x, y, vx, vy in path))


def face_at(t: float, x: float, y: float, z: float = 0.1) -> FaceSeen:
    d = math.sqrt(x * x + y * y + z * z)
    return FaceSeen(ns(t), d, math.atan2(y, x), math.atan2(z, math.hypot(x, y)))


def test_two_people_are_two_persons_with_their_bearings() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([targets(0.0, (2.0, 1.0), (3.0, -1.0))], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL"), (0.0, 2, "arrived", "SOCIAL")]
    one, two = model.state()
    assert (one.seen_by, two.seen_by) == (Sensor.RADAR, Sensor.RADAR)
    assert one.bearing_rad == one.yaw_rad == pytest.approx(math.atan2(1.0, 2.0))
    assert two.bearing_rad == pytest.approx(math.atan2(-1.0, 3.0))
    assert one.pitch_rad == 0.0  # never seen by the camera: level
    assert one.distance_m == pytest.approx(math.hypot(2.0, 1.0))


def test_crossing_people_keep_their_ids_then_leave() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([walk(0.0, 4.0, [(2.0, -2.0, 0.0, 1.0), (2.6, 2.0, 0.0, -1.0)]),
                targets(4.1), tick(10.0)], model)
    # The 3 s absence hold from the last report with them (4.0): the track's 1 s
    # coast overlaps it.
    assert rows == [(0.0, 1, "arrived", "SOCIAL"), (0.0, 2, "arrived", "SOCIAL"),
                    (7.0, 1, "engagement", "NONE->GONE"), (7.0, 1, "left", ""),
                    (7.0, 2, "engagement", "NONE->GONE"), (7.0, 2, "left", "")]


def test_crossing_people_end_on_the_other_side() -> None:
    model = PeopleModel(SETTINGS)
    run([walk(0.0, 4.0, [(2.0, -2.0, 0.0, 1.0), (2.6, 2.0, 0.0, -1.0)])], model)
    one, two = model.state()
    assert one.bearing_rad is not None and one.bearing_rad > 0.5  # walked to the left
    assert two.bearing_rad is not None and two.bearing_rad < -0.5


def test_a_face_at_a_radar_persons_bearing_is_that_person() -> None:
    model = PeopleModel(SETTINGS)
    run([walk(0.0, 1.0, [(2.0, 0.8, 0.0, 0.0), (2.0, -1.0, 0.0, 0.0)])], model)
    rows = run([face_at(1.05, 1.9, 0.78), targets(1.1, (2.0, 0.8), (2.0, -1.0)),
                face_at(1.15, 1.9, 0.78)], model)
    one, two = model.state()  # ids by position: 1 at y = -1, 2 at y = 0.8
    assert rows == [(1.05, 2, "engagement", "NONE->ENGAGING")]
    assert (one.seen_by, two.seen_by) == (Sensor.RADAR, Sensor.BOTH)
    assert two.yaw_rad == pytest.approx(math.atan2(0.78, 1.9))  # the face's, not the radar's
    assert two.distance_m == pytest.approx(math.sqrt(1.9**2 + 0.78**2 + 0.01))
    assert two.bearing_rad == pytest.approx(math.atan2(0.8, 2.0))


def test_a_face_away_from_every_track_is_a_person_of_its_own() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([targets(0.0, (2.0, 1.0)), face_at(0.05, 2.0, -1.0)], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL"), (0.05, 2, "arrived", "SOCIAL"),
                    (0.05, 2, "engagement", "NONE->ENGAGING")]
    assert [p.seen_by for p in model.state()] == [Sensor.RADAR, Sensor.CAMERA]


def test_the_camera_first_then_the_radar_is_one_person() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([face_at(0.0, 2.0, 0.2), targets(0.1, (2.05, 0.21)),
                face_at(0.15, 2.0, 0.2)], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL"), (0.0, 1, "engagement", "NONE->ENGAGING")]
    (one,) = model.state()
    assert one.seen_by is Sensor.BOTH
    assert one.bearing_rad is not None


def test_a_track_lost_and_found_nearby_is_the_same_person() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([walk(0.0, 0.5, [(2.0, 0.0, 0.0, 0.0)]), walk(0.6, 2.0, []),
                walk(2.1, 3.0, [(2.3, 0.2, 0.0, 0.0)])], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL")]
    (one,) = model.state()
    assert one.seen_by is Sensor.RADAR


def test_presence_does_not_add_a_person_while_angle_radars_report() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([targets(0.0, (2.0, 0.5)), RadarSeen(ns(0.05), True, 2.0),
                walk(0.1, 1.0, [(2.0, 0.5, 0.0, 0.0)])], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL")]


def test_presence_counts_again_once_angle_radars_are_silent() -> None:
    model = PeopleModel(SETTINGS)
    rows = run([targets(0.0), RadarSeen(ns(0.05), True, 2.0), tick(1.5),
                RadarSeen(ns(2.0), True, 1.0)], model)
    assert rows == [(2.0, 1, "arrived", "PERSONAL")]


def test_many_targets_are_bounded_by_max_tracks() -> None:
    model = PeopleModel(SETTINGS)
    inputs: list[Input] = [
        targets(i / 10, *((1.0 + j, -3.0 + 0.8 * i) for j in range(3)),
                sensor=(1, i)) for i in range(8)]
    run(inputs, model)
    assert len(model.state()) == SETTINGS.max_tracks
    assert model.tracks_refused > 0


def test_events_carry_the_reports_stamps() -> None:
    model = PeopleModel(SETTINGS)
    events = model.step(targets(12.345, (2.0, 0.0)))
    assert [row(e) for e in events] == [(12.345, 1, "arrived", "SOCIAL")]
