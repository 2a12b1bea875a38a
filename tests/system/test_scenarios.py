"""The whole simulated robot (`up --sim --scenario`) against the world's truth.

What a person in front of the robot would see, checked on the bus while
the real services run on one simulated world: greeted once per visit,
goodbye after they left, eyes asleep when nobody is there, the gaze on
the person, no greeting for someone who only walks past. `sim/world` says
what really happened, so each check is against the truth, not a script.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import available_services
from buddybot.tools.testing import Collector, Process, buddybot_argv, free_port, retry_until

pytestmark = pytest.mark.integration


@contextmanager
def robot_on(tmp_path: Path, scenario: str) -> Iterator[Node]:
    """`buddybot up --sim --scenario` on private ports; a probe on its router."""
    config = tmp_path / "robot.toml"
    config.write_text('[audio_player]\nbackend = "null"\n')
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--scenario", scenario,
                               "--listen", endpoint, "--config", str(config),
                               "--eye-port", str(free_port()), "--dashboard-port",
                               str(free_port()), "--status-period", "1"),
                 "up", tmp_path / "logs")
    probe: Node | None = None
    try:
        n = len([e for e in available_services() if not e.on_request])
        up.wait_for_output(f"nodes {n}/{n}", 180)
        probe = Node("probe", robot="buddy", connect=[endpoint], probe=True)
        yield probe
    finally:
        if probe is not None:
            probe.close()
        status = up.stop(30)
        print(up.output()[-6000:])
        assert status == 0


def sounds(states: list[m.ControllerState]) -> list[str]:
    """Each sound of ours, once, in the order it started."""
    out: list[str] = []
    for prev, cur in zip([None, *states], states, strict=False):
        if cur.sound and (prev is None or prev.sound != cur.sound):
            out.append(cur.sound)
    return out


def test_a_visit_is_greeted_once_followed_said_goodbye_to_and_the_eyes_sleep(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, "visit") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        gaze = Collector[m.EyesDirection](probe, keys.EYES_DIRECTION)
        # From the next time nobody is there to the end of the visit after it.
        empty = truth.wait_for(lambda w: not w.people, 120, "nobody in the world")
        lap = empty.lap + (1 if empty.t_s > 20 else 0)
        arrived = truth.wait_for(lambda w: w.lap == lap and any(
            p.in_camera for p in w.people), 120, "the visitor facing the camera")
        gone = truth.wait_for(lambda w: w.lap == lap and w.t_s > 30 and not w.people, 120,
                              "the visitor gone")
        retry_until(lambda: sounds(state.messages)[-1:] == ["farewell"], 60, 0.2, "goodbye")
        during = [s for s in state.messages if s.stamp_ns >= arrived.stamp_ns]
        assert sounds(during) == ["greeting", "farewell"], sounds(during)
        retry_until(lambda: state.messages[-1].expression == m.ExpressionAction.EYE_SLEEP,
                    60, 0.2, "asleep")
        # The gaze was on the visitor: to the robot's left, where they stood.
        looked = [d.yaw for d in gaze.messages if arrived.stamp_ns < d.stamp_ns < gone.stamp_ns]
        assert looked and sum(y > 0 for y in looked) > 0.8 * len(looked), looked[-20:]


def test_someone_walking_past_is_never_greeted(tmp_path: Path) -> None:
    with robot_on(tmp_path, "passer_by") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        first = truth.wait_for(lambda w: any(p.in_radar for p in w.people), 120, "a passer-by")
        truth.wait_for(lambda w: w.lap >= first.lap + 2, 120, "two more walks past")
        assert "greeting" not in sounds(state.messages), state.messages[-5:]


def test_in_the_dark_the_radar_alone_wakes_the_eyes_and_nobody_is_greeted(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, "dark") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        faces = Collector[m.FacePosition](probe, keys.FACE, camera="front")
        near = truth.wait_for(lambda w: any(p.distance_m < 1.2 for p in w.people), 120,
                              "the visitor close")
        assert not any(p.in_camera for p in near.people)  # the camera is covered
        retry_until(lambda: state.messages[-1].expression == m.ExpressionAction.EYE_AWAKE,
                    60, 0.2, "awake for a person only the radar sees")
        truth.wait_for(lambda w: w.lap > near.lap and w.t_s > 2, 120, "the next lap")
        assert "greeting" not in sounds(state.messages)
        assert faces.messages == []


def test_a_crowd_of_five_keeps_every_service_up_and_the_people_bounded(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, "crowd") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        people = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
        five = truth.wait_for(lambda w: len(w.people) == 5, 120, "five people")
        truth.wait_for(lambda w: w.lap > five.lap, 120, "a whole lap of the crowd")
        assert people.messages and max(len(s.people) for s in people.messages) <= 5
        live = probe.node_instances()
        expected = {e.name for e in available_services() if not e.on_request}
        assert expected <= {key.split("/")[-1] for key in live}, sorted(live)
