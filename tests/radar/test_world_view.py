"""The simulated world as the radars report it: the nearest targets, in each sensor's axes."""

from __future__ import annotations

import math

import pytest

from buddybot.radar import world_view as wv
from buddybot.radar.mounting import Mount, place
from buddybot.radar.sim_scene import BOTH, MOVING, NO_TARGET, STILL
from buddybot.sim import scenario
from buddybot.sim.world import ClutterState, PersonState, Snapshot, World


def person(pid: int, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> PersonState:
    return PersonState(pid, "", "collins", x, y, 0.2, vx, vy, math.atan2(-y, -x))


def snap(*people: PersonState, clutter: tuple[ClutterState, ...] = ()) -> Snapshot:
    return Snapshot(1.0, 0, people, clutter, False)


def test_nobody_in_the_field_is_no_target() -> None:
    assert wv.ld2410_target(snap()).state == NO_TARGET
    behind = person(1, -1.0, 0.0)
    too_far = person(2, 7.0, 0.0)
    aside = person(3, 0.5, 2.0)  # 76 degrees off the sensor's axis
    assert wv.ld2410_target(snap(behind, too_far, aside)).state == NO_TARGET


def test_a_standing_person_is_a_still_target_a_walking_one_a_moving_target() -> None:
    still = wv.ld2410_target(snap(person(1, 1.0, 0.0)))
    assert (still.state, still.still_cm) == (STILL, 100) and still.still_energy > 50
    walking = wv.ld2410_target(snap(person(1, 2.0, 0.0, vx=-0.8)))
    assert (walking.state, walking.moving_cm) == (MOVING, 200)
    both = wv.ld2410_target(snap(person(1, 1.5, 0.0), person(2, 3.0, 0.5, vx=-1.0)))
    assert (both.state, both.still_cm, both.moving_cm, both.detection_cm) == (
        BOTH, 150, 304, 150)


def test_energy_falls_with_distance() -> None:
    near = wv.ld2410_target(snap(person(1, 1.0, 0.0))).still_energy
    far = wv.ld2410_target(snap(person(1, 5.0, 0.0))).still_energy
    assert near > far > 0


def test_a_fan_moves_and_a_ghost_stands_for_the_radar() -> None:
    fan = wv.ld2410_target(snap(clutter=(ClutterState("fan", 1.5, 0.8),)))
    assert fan.state == MOVING and fan.moving_cm == round(math.hypot(1.5, 0.8) * 100)
    ghost = wv.ld2410_target(snap(clutter=(ClutterState("ghost", 2.0, 0.0),)))
    assert ghost.state == STILL and ghost.still_energy < wv.ld2410_target(
        snap(person(1, 2.0, 0.0))).still_energy


@pytest.mark.parametrize("mount", [
    Mount(), Mount(yaw=0.4), Mount(x=0.05, y=-0.1, yaw=-0.6), Mount(mirror_x=True),
    Mount(y=0.2, yaw=0.3, mirror_x=True)])
def test_an_ld2450_target_placed_back_through_its_mount_is_where_the_person_is(
        mount: Mount) -> None:
    people = (person(1, 1.5, 0.4), person(2, 2.5, -0.6), person(3, 0.9, 0.1))
    scene = wv.ld2450_scene(snap(*people), mount)
    assert len(scene.people) == 3
    for target in scene.people:
        placed = place(target.x_mm / 1000, target.y_mm / 1000, mount)
        nearest = min(people, key=lambda p: math.hypot(p.x - placed.x, p.y - placed.y))
        assert math.hypot(nearest.x - placed.x, nearest.y - placed.y) < 0.002


def test_a_person_to_the_robots_left_has_negative_x_on_an_upright_sensor() -> None:
    scene = wv.ld2450_scene(snap(person(1, 2.0, 0.5)), Mount())
    assert scene.people[0].x_mm == -500 and scene.people[0].y_mm == 2000


def test_the_ld2450_reports_the_nearest_three_with_their_radial_speed() -> None:
    people = [person(i, 1.0 + i * 0.5, 0.0, vx=0.5 if i == 1 else 0.0) for i in range(1, 6)]
    scene = wv.ld2450_scene(snap(*people), Mount())
    assert [t.y_mm for t in scene.people] == [1500, 2000, 2500]
    assert scene.people[0].speed_cms == 50  # leaving: positive


def test_the_simulated_radars_see_the_visit_come_and_go() -> None:
    w = World(scenario.load("visit"))
    ld2410 = wv.world_script(w, "LD2410", Mount())
    ld2450 = wv.world_script(w, "LD2450", Mount())
    assert ld2410(10.0, None).still_cm == pytest.approx(100, abs=5)  # type: ignore[arg-type, union-attr]
    assert ld2410(35.0, None).state == NO_TARGET  # type: ignore[arg-type, union-attr]
    assert len(ld2450(10.0, None).people) == 1  # type: ignore[arg-type, union-attr]
