"""A face that is alive, through the real services on the simulated world (`up --sim`).

What a visitor would notice, checked against the world's truth (`sim/world`):
the passer-by is looked at and never greeted; with two people the eyes go to
the newcomer within 1.5 s and visit each of them while both stand there; a
person only an angle radar sees is looked at before any face is seen. (The
goodbye as a visitor turns to leave, and a gaze that moves yet rests on a
standing visitor's face, are checked on the same robot as the rest of a
visit: test_scenarios.py.)
"""

from __future__ import annotations

import bisect
import math
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.tools.testing import Collector
from tests.sim import SCENARIOS
from tests.system.robot import robot_on, sounds

pytestmark = [pytest.mark.integration, pytest.mark.robot]

LD2450 = '[radar_bridge]\nsim_model = "LD2450"\n'
"""An angle radar instead of the LD2410: every person has a bearing."""
ON_DEG = 10.0
"""The gaze is on a person when its yaw is within this of their true bearing."""


class Gazes:
    """The eyes' direction and the world's truth, matched by stamp."""

    def __init__(self, truth: Collector[m.SimWorld], gaze: Collector[m.EyesDirection]
                 ) -> None:
        self.truth, self.gaze = truth, gaze

    def world_at(self, stamp_ns: int) -> m.SimWorld | None:
        worlds = list(self.truth.messages)
        i = bisect.bisect_right([w.stamp_ns for w in worlds], stamp_ns)
        return worlds[i - 1] if i else None

    def on(self, person_id: int, since_ns: int, until_ns: int) -> list[int]:
        """Stamps of the gazes within `ON_DEG` of where `person_id` really was."""
        out = []
        for d in list(self.gaze.messages):
            if not since_ns <= d.stamp_ns <= until_ns:
                continue
            world = self.world_at(d.stamp_ns)
            p = next((p for p in world.people if p.id == person_id), None) if world else None
            if p is not None and abs(d.yaw - math.degrees(p.bearing_rad)) <= ON_DEG:
                out.append(d.stamp_ns)
        return out


def test_a_passer_by_is_looked_at_and_never_greeted(tmp_path: Path) -> None:
    with robot_on(tmp_path, "passer_by", LD2450) as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        gazes = Gazes(truth, Collector[m.EyesDirection](probe, keys.EYES_DIRECTION))
        first = truth.wait_for(lambda w: any(p.in_radar for p in w.people), 120,
                               "a passer-by")
        last = truth.wait_for(lambda w: w.lap >= first.lap + 2, 120, "two more walks past")
        assert gazes.on(1, first.stamp_ns, last.stamp_ns), "never looked at the passer-by"
        assert "greeting" not in sounds(state.messages), state.messages[-5:]


def test_two_people_the_newcomer_is_glanced_at_and_both_are_looked_at(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, str(SCENARIOS / "two_people_once.toml"), LD2450) as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        gazes = Gazes(truth, Collector[m.EyesDirection](probe, keys.EYES_DIRECTION))
        came = truth.wait_for(lambda w: any(p.id == 2 and p.in_radar for p in w.people),
                              120, "the second person in the radar's field")
        assert any(p.id == 1 for p in came.people)
        standing = truth.wait_for(lambda w: w.t_s >= 14, 120, "both standing")
        end = truth.wait_for(lambda w: w.t_s >= 30, 120, "both still there")
        newcomer = gazes.on(2, came.stamp_ns, came.stamp_ns + 15 * 10**8)
        assert newcomer, "the eyes did not go to the newcomer within 1.5 s"
        assert gazes.on(1, standing.stamp_ns, end.stamp_ns), "never on the first person"
        assert gazes.on(2, standing.stamp_ns, end.stamp_ns), "never on the second person"


def test_a_person_only_the_angle_radar_sees_is_looked_at_before_any_face(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, "out_of_view", LD2450) as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        faces = Collector[m.FacePosition](probe, keys.FACE, camera="front")
        gazes = Gazes(truth, Collector[m.EyesDirection](probe, keys.EYES_DIRECTION))
        lap = truth.wait_for(lambda w: w.lap >= 1 and w.t_s < 5, 120, "a new lap").lap
        start = truth.wait_for(lambda w: w.lap == lap, 1, "the lap's start").stamp_ns
        face = faces.wait_for(lambda f: f.stamp_ns > start, 60, "their face")
        looked = gazes.on(1, start, face.stamp_ns)
        assert looked, "the eyes did not turn to the radar's person before the face"
