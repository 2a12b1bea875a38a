"""A full simulated visit through a real router, every service its own process.

The simulated LD2410 (behind a pty) and the camera see one simulated
visitor (a real face photo) who walks in from 4 m, stands at 1 m on the
robot's left, then on its right, and leaves. The robot must
wake its eyes, look the right way, greet on the null audio device, say
goodbye once the visitor has gone, and go back to sleep.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.controller.settings import ControllerSettings
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, retry_until

from .robot import (
    BASE_SERVICES,
    FAREWELL_S,
    GREETING_S,
    Spawn,
    start_robot,
    start_world,
    wait_nodes,
)

pytestmark = [pytest.mark.integration, pytest.mark.robot]  # a router and the robot's processes

A = m.ExpressionAction


def sounds_played(status: Collector[m.PlaySoundStatus]) -> list[str]:
    """Goals that SUCCEEDED, in order, told apart by length (PLAYING says "<s> s")."""
    lengths: dict[str, float] = {}
    done: list[str] = []
    for s in status.messages:
        if s.state == "PLAYING" and s.message.endswith(" s"):
            lengths[s.goal_id] = float(s.message.split()[0])
        if s.state == "SUCCEEDED" and s.goal_id in lengths and s.goal_id not in done:
            done.append(s.goal_id)
    return ["greeting" if abs(lengths[g] - GREETING_S) < 0.05 else
            "farewell" if abs(lengths[g] - FAREWELL_S) < 0.05 else f"?{lengths[g]}"
            for g in done]


def test_visit_wakes_follows_greets_says_goodbye_and_sleeps(
    probe: Node, spawn: Spawn, tmp_path: Path
) -> None:
    expression = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    lids = Collector[m.EyeLidControl](probe, keys.LIDS)
    faces = Collector[m.FacePosition](probe, keys.FACE, camera="front")
    direction = Collector[m.EyesDirection](probe, keys.EYES_DIRECTION)
    status = Collector[m.PlaySoundStatus](probe, keys.PLAY_SOUND_STATUS)
    procs = start_robot(spawn, tmp_path, camera=False)
    wait_nodes(probe, list(BASE_SERVICES))
    procs |= start_world(spawn, "left_right", tmp_path / "config" / "robot.toml")

    # Eyes wake (and the lids open) when the visitor comes within range.
    expression.wait_for(lambda e: e.action == A.EYE_AWAKE, 60, "EYE_AWAKE")
    lids.wait_for(lambda x: x.top_lid_position == 0 and x.bottom_lid_position == 0, 20,
                  "open lids")

    # The gaze follows the face with the right signs, matched by the face's stamp.
    # Only faces further aside than a gaze aversion count: an aversion turns the
    # eyes `aversion_deg` away on purpose, across the middle for a face near it.
    aside_deg = ControllerSettings().aversion_deg + 3.0

    def pairs_by_direction() -> list[tuple[m.EyesDirection, float]]:
        by_stamp = {f.stamp_ns: f.point for f in faces.messages}
        return [(d, by_stamp[d.stamp_ns].y) for d in direction.messages
                if d.stamp_ns in by_stamp and abs(math.degrees(math.atan2(
                    by_stamp[d.stamp_ns].y, by_stamp[d.stamp_ns].x))) > aside_deg]

    def signs_seen() -> bool:
        pairs = pairs_by_direction()
        wrong = [(d, y) for d, y in pairs if (y > 0) != (d.yaw > 0)]
        assert not wrong, wrong[:5]
        return any(y > 0 for _, y in pairs) and any(y < 0 for _, y in pairs)

    retry_until(signs_seen, 60, 0.2, "gaze left and right")

    # Greeting, then (visitor gone) farewell, each played to the end once.
    retry_until(lambda: sounds_played(status)[:1] == ["greeting"], 60, 0.2, "greeting played")
    retry_until(lambda: sounds_played(status) == ["greeting", "farewell"], 60, 0.2,
                "farewell played")
    # ... and the eyes go back to sleep (the first SLEEP was the robot's initial state).
    def asleep_again() -> bool:
        actions = [e.action for e in expression.messages]
        return actions[-1] == A.EYE_SLEEP and A.EYE_AWAKE in actions
    retry_until(asleep_again, 30, 0.1, "EYE_SLEEP after the visit")
    retry_until(lambda: (last := lids.messages[-1]).top_lid_position == 50
                and last.bottom_lid_position == 50, 20, 0.1, "closed lids")

    actions = [e.action for e in expression.messages]
    assert all(a != b for a, b in itertools.pairwise(actions)), actions
    for name, proc in procs.items():
        assert proc.alive(), f"{name} died:\n{proc.output()[-3000:]}"
