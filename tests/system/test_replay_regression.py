"""Regression from a recording: a simulated visit, recorded, replayed into fresh services.

Live run: the robot (every service, the camera and the simulated LD2410
seeing one simulated visitor) on router A, recorded with
`buddybot bag record --images`. Replay: the recording's sensor keys only
(radar frames and camera images) played on router B into fresh
radar-presence, people, face-detector, controller, eyes, audio and audio-player
processes, with no radar bridge and no camera. The decisions must be the
same: the same sequence of expressions, and exactly one greeting and one
farewell, as in the live run.
"""

from __future__ import annotations

import itertools
import signal
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Collector,
    Process,
    Router,
    buddybot_argv,
    retry_until,
    run_service,
    stop_and_report,
)

from .robot import BASE_SERVICES, Spawn, start_robot, start_world, wait_nodes, write_config
from .test_visit import sounds_played

pytestmark = [pytest.mark.integration, pytest.mark.robot]  # two routers and the robot's processes

A = m.ExpressionAction
SENSOR_KEYS = ("radar/*/frames", "camera/*/image")


def actions(expression: Collector[m.ScreenExpression]) -> list[A]:
    """The expressions in order, repeats of the same one folded."""
    return [a for a, _ in itertools.groupby(e.action for e in expression.messages)]


def wait_visit_done(expression: Collector[m.ScreenExpression],
                    status: Collector[m.PlaySoundStatus], what: str) -> None:
    retry_until(lambda: sounds_played(status)[:1] == ["greeting"], 90, 0.2,
                f"{what}: greeting played")
    retry_until(lambda: sounds_played(status) == ["greeting", "farewell"], 90, 0.2,
                f"{what}: farewell played")
    retry_until(lambda: actions(expression)[-1] == A.EYE_SLEEP
                and A.EYE_AWAKE in actions(expression), 60, 0.1, f"{what}: asleep again")


def test_a_recorded_visit_replays_into_the_same_decisions(
    probe: Node, spawn: Spawn, endpoint: str, tmp_path: Path, log_dir: Path
) -> None:
    recording = tmp_path / "visit.mcap"

    # --- live: the whole simulated robot, recorded -------------------------------
    live_expression = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    live_status = Collector[m.PlaySoundStatus](probe, keys.PLAY_SOUND_STATUS)
    live = start_robot(spawn, tmp_path / "live", camera=False)
    wait_nodes(probe, list(BASE_SERVICES))
    recorder = Process(buddybot_argv("bag", "record", "-o", str(recording), "--images",
                                     "--connect", endpoint), "bag-record", log_dir)
    try:
        # A camera nobody else watches: only the recorder's `camera/*/image` (declared
        # last) matches it, so its matching says the recorder listens to everything.
        with probe.raw_publisher(keys.absolute("buddy",
                                               keys.CAMERA_IMAGE.key(camera="unseen")),
                                 keys.CAMERA_IMAGE.encoding) as unseen:
            retry_until(unseen.has_subscribers, 30, 0.1, "the recorder subscribed")
        live |= start_world(spawn, "walk_in", tmp_path / "live" / "config" / "robot.toml")
        wait_visit_done(live_expression, live_status, "live")
        recorder.send_signal(signal.SIGTERM)
        assert recorder.proc.wait(60) == 0, recorder.output()
    finally:
        recorder.stop()  # also when the live part failed: no recorder left behind
    for proc in live.values():  # the replay must not compete with them for the CPU
        proc.stop()
    live_actions = actions(live_expression)
    print("live expressions:", [a.name for a in live_actions])
    assert sounds_played(live_status) == ["greeting", "farewell"]

    # --- replay: fresh services on another router, sensors from the file only ---
    router = Router(log_dir=log_dir / "replay")
    started: list[Process] = [router]
    node: Node | None = None
    try:
        config = write_config(tmp_path / "replay-config")
        for name, args in BASE_SERVICES.items():
            started.append(run_service(name, router.endpoint, "--config", str(config), *args,
                                       log_dir=log_dir / "replay"))
        node = Node("replay-probe", connect=[router.endpoint])
        expression = Collector[m.ScreenExpression](node, keys.EXPRESSION)
        status = Collector[m.PlaySoundStatus](node, keys.PLAY_SOUND_STATUS)
        wait_nodes(node, list(BASE_SERVICES))
        player = Process(buddybot_argv("bag", "play", str(recording), "--keys", *SENSOR_KEYS,
                                       "--connect", router.endpoint), "bag-play",
                         log_dir / "replay")
        started.append(player)
        wait_visit_done(expression, status, "replay")
        assert player.proc.wait(120) == 0, player.output()
        assert "played" in player.output() and "(stopped)" not in player.output()
        assert sounds_played(status) == ["greeting", "farewell"]
        assert actions(expression) == live_actions
        for proc in started[1:-1]:
            assert proc.alive(), f"{proc.name} died:\n{proc.output()[-3000:]}"
    finally:
        if node is not None:
            node.close()
        stop_and_report(started)

