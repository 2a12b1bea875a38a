"""The simulated world as a function of time: the built-in scenarios do what they say."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from buddybot.sim import scenario, views
from buddybot.sim.world import SWAY_M, Snapshot, World
from tests.properties import examples

LENS = views.Lens(600.0, 600.0, 320.0, 240.0, 640, 480)
"""The detector's default pinhole on the simulated camera's default frame (56 deg wide)."""


def world(name: str, seed: int = 0) -> World:
    return World(scenario.load(name), seed)


def times(w: World, step: float = 0.1) -> list[float]:
    n = round(w.scenario.spec.length_s / step)
    return [i * step for i in range(n)]


def on_camera(snap: Snapshot) -> set[int]:
    return {f.person.id for f in views.camera_view(snap, LENS) if f.visible}


@given(st.sampled_from(scenario.builtin_names()), st.floats(0, 500), st.integers(0, 2**31 - 1))
@settings(max_examples=examples(200))
def test_the_world_is_a_pure_function_of_time_and_seed(name: str, t: float, seed: int) -> None:
    assert world(name, seed).at(t) == world(name, seed).at(t)


@given(st.integers(0, 1000), st.floats(4.5, 23.5))
@settings(max_examples=examples(100))
def test_a_standing_person_sways_a_little_whatever_the_seed(seed: int, t: float) -> None:
    person = world("visit", seed).at(t).people[0]
    assert math.hypot(person.x - 1.0, person.y - 0.1) <= SWAY_M * 1.5
    assert person.turned < 0.05  # facing the robot


def test_visit_comes_close_stays_about_20_s_facing_the_robot_and_leaves_every_loop() -> None:
    w = world("visit")
    close = [t for t in times(w) if (p := w.at(t).people) and p[0].distance < 1.2]
    assert 19.0 <= close[-1] - close[0] <= 22.0
    assert all(1 in on_camera(w.at(t)) for t in close[:-15])
    gone = [t for t in times(w) if not w.at(t).people]
    assert gone and gone[0] > close[-1]
    assert max(p.distance for t in times(w) for p in w.at(t).people) >= 4.9  # out of range
    assert w.at(40.0 + 10.0).people == w.at(10.0).people and w.at(50.0).lap == 1


def test_the_passer_by_never_approaches_never_stops_and_shows_no_face() -> None:
    w = world("passer_by")
    seen = [p for t in times(w, 0.05) for p in w.at(t).people]
    assert seen and all(abs(p.x - 1.5) < 1e-9 for p in seen)
    assert all(math.hypot(p.vx, p.vy) > 1.0 for p in seen)  # walking speed, never still
    assert all(p.vy < 0 for p in seen)  # the robot's left to its right
    assert min(p.distance for p in seen) == pytest.approx(1.5, abs=0.01)
    assert not any(on_camera(w.at(t)) for t in times(w, 0.05))  # in profile: no face


def test_two_people_arrive_8_s_apart_stay_together_and_leave_one_after_the_other() -> None:
    w = world("two_people")

    def first(pid: int, cond: str) -> float:
        for t in times(w):
            p = next((p for p in w.at(t).people if p.id == pid), None)
            near = p is not None and p.distance < 2.0
            if (cond == "near" and near) or (cond == "far" and t > 20 and not near):
                return t
        raise AssertionError(pid)

    assert first(2, "near") - first(1, "near") == pytest.approx(8.0, abs=0.3)
    together = [t for t in times(w) if len(on_camera(w.at(t))) == 2]
    assert together[-1] - together[0] >= 19.5
    assert first(2, "far") - first(1, "far") == pytest.approx(8.0, abs=0.5)
    assert {p.name for p in w.at(20).people} == {"Barack", "Joe"}


def test_out_of_view_stands_at_50_degrees_where_only_a_radar_sees_then_comes_into_view() -> None:
    w = world("out_of_view")
    for t in (0.0, 5.0, 9.5):
        person = w.at(t).people[0]
        assert math.degrees(person.bearing) == pytest.approx(50.0, abs=2.0)
        assert person.distance == pytest.approx(2.0, abs=0.05)
        assert not on_camera(w.at(t))
        assert views.radar_sees(person.x, person.y, views.AT_CAMERA, views.LD2450_FIELD)
    assert on_camera(w.at(15.0)) == {1}


def test_return_brings_the_same_named_person_back_after_15_s_away() -> None:
    w = world("return")
    present = [t for t in times(w) if w.at(t).people]
    gaps = [b - a for a, b in itertools.pairwise(present) if b - a > 1.0]
    assert len(gaps) == 1 and gaps[0] == pytest.approx(15.0, abs=0.2)
    assert {p.name for t in present for p in w.at(t).people} == {"Eileen"}
    assert w.at(500.0).people == ()  # it runs once


def test_dark_covers_the_camera_while_the_radar_sees_the_visit() -> None:
    w = world("dark")
    snap = w.at(10.0)
    assert snap.camera_covered and snap.people and not on_camera(snap)
    assert views.radar_sees(snap.people[0].x, snap.people[0].y, views.AT_CAMERA,
                            views.LD2410_FIELD)


def test_crowd_has_five_people_at_once_and_hides_some_behind_others() -> None:
    w = world("crowd")
    assert max(len(w.at(t).people) for t in times(w)) == 5
    hidden = [t for t in times(w) if any(
        not f.visible and f.person.turned < views.MAX_TURN_RAD and 0 <= f.u < LENS.width
        for f in views.camera_view(w.at(t), LENS))]
    assert hidden  # someone turned to the camera, in the frame, behind someone nearer


def test_ghost_is_a_fan_for_3_minutes_then_a_visit() -> None:
    w = world("ghost")
    assert all(not w.at(t).people and w.at(t).clutter for t in range(0, 180, 5))
    assert w.at(190.0).people and w.at(190.0).clutter[0].kind == "fan"
