"""LD2450 scenarios: pure functions of time, people in the sensor's axes."""

from __future__ import annotations

import random

import pytest

from buddybot.radar import ld2450 as p
from tests.radar.scripts import LD2450_SCRIPTS as ANGLE_SCENARIOS
from tests.radar.scripts import crossing, three_people


def test_crossing_goes_from_the_robots_left_to_its_right_approaching_then_leaving() -> None:
    rng = random.Random(1)
    xs = [crossing(t / 10, rng).people[0].x_mm for t in range(0, 70)]
    assert xs[0] == -3500 and xs[-1] > 3300 and xs == sorted(xs)
    assert crossing(2.0, rng).people[0].speed_cms < 0 < crossing(5.0, rng).people[0].speed_cms
    assert crossing(8.0, rng).people == ()


def test_three_people_at_once() -> None:
    assert len(three_people(3.0, random.Random(1)).people) == 3


@pytest.mark.parametrize("name", sorted(ANGLE_SCENARIOS))
def test_every_scenario_fits_the_sensor(name: str) -> None:
    rng = random.Random(2)
    for i in range(300):
        scene = ANGLE_SCENARIOS[name](i * 0.1, rng)
        assert len(scene.people) <= p.SLOTS
        for person in scene.people:
            target = p.Target(person.x_mm, person.y_mm, person.speed_cms, 320)
            assert target.plausible(), (name, person)
