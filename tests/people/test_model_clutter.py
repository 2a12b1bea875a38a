"""Clutter is not a person: a radar target that the camera never confirms and that
never moves through the room (a fan, a curtain) stops counting after
`clutter_after_s`, and its place stays clutter until the radar's picture there
changes; a face, or someone walking through, brings a person back.

Settings as in test_model.py, with `clutter_after_s` 20 s and `clutter_spread_m`
0.8 m (the defaults); LD2410 frames and LD2450 reports every 0.1 s.
"""

from __future__ import annotations

from collections.abc import Iterator

import msgspec

from buddybot.people.model import Input, PeopleModel, RangeSeen

from .test_model import SETTINGS, faces, ns, radar, radar_out, run, tick
from .test_model_radar import walk

CLUTTER = msgspec.structs.replace(SETTINGS, clutter_after_s=20.0, clutter_spread_m=0.8)
LD2410 = (0, 0)


def ranges(start: float, end: float, near: float, far: float | None = None,
           ) -> Iterator[RangeSeen]:
    """LD2410 frames every 0.1 s, the nearest target going from `near` to `far`."""
    far = near if far is None else far
    n = round((end - start) * 10)
    for i in range(n + 1):
        yield RangeSeen(ns(start + i / 10), LD2410, near + (far - near) * i / max(n, 1))


def fan(start: float, end: float) -> list[Input | Iterator[Input]]:
    """A fan 1.7 m away from `start`: radar presence IN_RANGE, and the frames."""
    return [radar(start, 1.7), ranges(start, end, 1.7)]


def test_a_fan_stops_counting_after_the_clutter_time_and_stays_clutter() -> None:
    model = PeopleModel(CLUTTER)
    rows = run([*fan(0.0, 60.0)], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL"), (20.0, 1, "engagement", "NONE->GONE"),
                    (20.0, 1, "left", "")]
    assert model.state() == () and model.clutter == 1


def test_someone_nearer_than_the_fan_is_a_person_and_leaves_the_fan_behind() -> None:
    model = PeopleModel(CLUTTER)
    run([*fan(0.0, 30.0)], model)
    # Someone walks in front of it: the LD2410's nearest target comes off the spot.
    rows = run([ranges(30.1, 33.0, 1.7, 0.6), ranges(33.1, 60.0, 0.6)], model)
    assert rows[0][1:3] == (2, "arrived")
    assert 32.0 < rows[0][0] < 32.5  # once more than 0.8 m nearer than the fan (0.38 m/s)
    assert [p.id for p in model.state()] == [2]  # walked in: never taken for clutter
    # They leave: the fan is nearest again, clutter as before, and they are gone.
    rows = run([ranges(60.1, 61.0, 0.6, 1.7), ranges(61.1, 70.0, 1.7), tick(70.0)], model)
    assert [r[2] for r in rows] == ["engagement", "left"] and model.state() == ()


def test_a_face_at_the_spot_is_a_person_at_once() -> None:
    model = PeopleModel(CLUTTER)
    run([*fan(0.0, 30.0)], model)
    rows = run([ranges(30.1, 40.0, 1.7), faces(30.5, 40.0, 1.7)], model)
    assert rows[0][1:] == (2, "arrived", "SOCIAL")
    assert [p.id for p in model.state()] == [2]


def test_someone_who_walked_in_and_stands_still_without_a_face_is_no_clutter() -> None:
    model = PeopleModel(CLUTTER)
    run([radar(0.0, 2.5), ranges(0.0, 3.0, 2.5, 1.0), ranges(3.1, 120.0, 1.0)], model)
    assert [p.id for p in model.state()] == [1] and model.clutter == 0


def test_the_spot_is_forgotten_once_the_radar_shows_nothing_there() -> None:
    model = PeopleModel(CLUTTER)
    run([*fan(0.0, 30.0)], model)
    # Switched off for longer than the clutter time: the radar shows nobody.
    run([radar_out(30.1), (RangeSeen(ns(30.1 + i / 10), LD2410, None)
                           for i in range(250))], model)
    rows = run([*fan(56.0, 60.0)], model)  # on again: a person until shown otherwise
    assert rows == [(56.0, 2, "arrived", "SOCIAL")]


def test_the_clutter_time_is_live() -> None:
    model = PeopleModel(CLUTTER)
    run([*fan(0.0, 5.0)], model)
    model.s = msgspec.structs.replace(CLUTTER, clutter_after_s=5.0)
    rows = run([ranges(5.1, 6.0, 1.7)], model)
    assert rows[-1][2] == "left" and rows[-1][0] == 5.0  # at arrival + the new time


def test_without_ld2410_frames_nothing_is_taken_for_clutter() -> None:
    """Radar presence alone says nothing about movement: nobody is clutter."""
    model = PeopleModel(CLUTTER)
    run([radar(0.0, 1.7), tick(120.0)], model)
    assert [p.id for p in model.state()] == [1]


# --- angle radars ------------------------------------------------------------------------


def test_a_still_angle_radar_target_is_clutter_and_a_walker_through_its_spot_is_not(
        ) -> None:
    model = PeopleModel(CLUTTER)
    rows = run([walk(0.0, 30.0, [(1.5, 0.8, 0.0, 0.0)])], model)
    assert rows == [(0.0, 1, "arrived", "SOCIAL"), (20.0, 1, "engagement", "NONE->GONE"),
                    (20.0, 1, "left", "")]
    # The ghost's track goes on: no person; someone walks from far through the room.
    rows = run([walk(30.1, 34.0, [(1.5, 0.8, 0.0, 0.0), (4.0, -1.0, -0.5, 0.0)])], model)
    assert [r[1:3] for r in rows if r[2] != "zone"] == [(2, "arrived")]
    assert [p.id for p in model.state()] == [2]


def test_a_ghost_that_starts_to_move_is_a_person_again() -> None:
    model = PeopleModel(CLUTTER)
    run([walk(0.0, 30.0, [(1.5, 0.8, 0.0, 0.0)])], model)
    rows = run([walk(30.1, 33.0, [(1.5, 0.8, 0.0, -0.5)])], model)  # off the spot
    assert [r[1:3] for r in rows] == [(2, "arrived")]
