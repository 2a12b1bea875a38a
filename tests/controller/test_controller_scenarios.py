"""The controller as its own process behind the real router, a fake audio action
server and a radar/camera stimulus as real Zenoh nodes: one visit end to end (the
wiring), and what only a process shows (garbage on the wire, a restart that reads
the latched inputs, the exit code of a bad config, the camera it subscribes to,
stamps checked on arrival). What the behaviour decides in a visit is tested
without processes in test_controller_scenes.py."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, retry_until

X = m.ExpressionAction
pytestmark = pytest.mark.integration

Spawn = Callable[..., Process]


def expressions(col: Collector[m.ScreenExpression]) -> list[X]:
    return [msg.action for msg in col.messages]


def wait_expressions(col: Collector[m.ScreenExpression], tail: list[X],
                     timeout: float = 15.0) -> list[X]:
    """Wait until the expressions published so far end with `tail`."""
    return retry_until(lambda: expressions(col)[-len(tail):] == tail and expressions(col),
                       timeout, what=f"expressions ending with {tail}")


def no_repeats(seq: list[X]) -> bool:
    return all(a != b for a, b in itertools.pairwise(seq))


@pytest.fixture
def watch(probe: Node) -> tuple[Collector[m.ScreenExpression], Collector[m.EyeControl]]:
    return Collector(probe, keys.EXPRESSION), Collector(probe, keys.EYE_CONTROL)


def start_controller(spawn: Spawn, config: Path,
                     expr: Collector[m.ScreenExpression]) -> Process:
    proc = spawn("controller", "--config", str(config))
    # Up and past its recovery window: it has published the eyes' state.
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, timeout=20, what="initial EYE_SLEEP")
    return proc


def test_approach_greet_follow_leave_farewell(spawn, fast_config, stimulus, make_audio,
                                              watch, probe) -> None:
    """Every key the controller reads and writes, through the router: presence, faces,
    the audio action and device-free in; expressions, eye control and its state out."""
    expr, control = watch
    states: Collector[m.ControllerState] = Collector(probe, keys.CONTROLLER_STATE)
    audio = make_audio(durations={"greeting": 0.8, "farewell": 0.8})
    proc = start_controller(spawn, fast_config, expr)

    stimulus.presence(True)
    wait_expressions(expr, [X.EYE_AWAKE])
    stimulus.watch(True)
    audio.wait_log(lambda log: "play:greeting" in log, what="greeting")
    wait_expressions(expr, [X.EYE_GRIN])
    audio.wait_log(lambda log: "end:greeting" in log)
    wait_expressions(expr, [X.EYE_AWAKE])
    states.wait_for(lambda st: st.phase == "engaged" and st.greeted and st.sound is None,
                    what="state: engaged, greeted, the greeting over")

    # Following: a face to the left and up gives +yaw, +pitch, its stamp kept.
    stimulus.watch(False)
    stimulus.point = m.Point(x=1.0, y=0.5, z=0.2)
    stamp = stimulus.face()
    msg = control.wait_for(lambda c: c.stamp_ns == stamp, what="eye control of that face")
    # camera 10 cm above the eyes centre (FAST_CONFIG): z = 0.3 in the eyes frame
    assert msg.yaw == pytest.approx(math.atan2(0.5, 1.0))
    assert msg.pitch == pytest.approx(math.atan2(0.3, math.hypot(1.0, 0.5)))
    assert msg.target_distance_cm == pytest.approx(math.sqrt(1.0 + 0.25 + 0.09) * 100)

    stimulus.presence(False)
    audio.wait_log(lambda log: "play:farewell" in log, what="farewell")
    seq = wait_expressions(expr, [X.EYE_SLEEPY, X.EYE_SLEEP])
    assert audio.sounds() == ["greeting", "farewell"]
    assert audio.overlaps == 0
    assert no_repeats(seq), seq
    assert seq == [X.EYE_SLEEP, X.EYE_AWAKE, X.EYE_GRIN, X.EYE_AWAKE, X.EYE_SLEEPY, X.EYE_SLEEP]
    assert proc.alive()


MALFORMED: list[bytes] = [
    b"", b"\xff\xfe garbage", b"{", b"[]", b"null", b'{"stamp_ns": -1}',
    b'{"stamp_ns": 1, "presence_state": 7, "target_state": 0, "distance_m": 1.0}',
    b'{"stamp_ns": 1, "frame_id": "f", "point": {"x": 1e999, "y": 0, "z": 0}, '
    b'"confidence": 0.5}',
    b'{"stamp_ns": 1, "frame_id": "f", "point": {"x": "a", "y": 0, "z": 0}, '
    b'"confidence": 0.5}',
    b'{"goal_id": "x", "state": "EXPLODED"}', b'{"stamp_ns": 1, "data": "yes"}',
    b'{"stamp_ns": 1, "action": 99}', b"x" * 100_000,
]


def test_malformed_payloads_on_every_input_are_survived(spawn, fast_config, stimulus,
                                                         make_audio, watch, endpoint) -> None:
    expr, control = watch
    audio = make_audio(durations={"greeting": 0.3})
    proc = start_controller(spawn, fast_config, expr)
    inputs = [keys.PRESENCE.key(), keys.FACE.key(camera="front"), keys.DEVICE_FREE.key(),
              keys.PLAY_SOUND_STATUS.key(), keys.EXPRESSION.key()]
    with zenoh.open(_probe_config(endpoint)) as session:
        for rel in inputs:
            for payload in MALFORMED:
                session.put(keys.absolute("buddy", rel), payload)
        # A face point that decodes but is not finite never reaches the eyes.
        bad_stamp = m.now_ns()
        session.put(keys.absolute("buddy", keys.FACE.key(camera="front")),
                    b'{"stamp_ns": %d, "frame_id": "f", "point": {"x": 1e999, "y": 0, "z": 0},'
                    b' "confidence": 0.5}' % bad_stamp)
    # Still working end to end: follows faces, greets, says goodbye.
    stamp = stimulus.face()
    control.wait_for(lambda c: c.stamp_ns == stamp, what="eye control after garbage")
    stimulus.presence(True)
    stimulus.watch(True)
    audio.wait_log(lambda log: "end:greeting" in log, what="greeting after garbage")
    stimulus.presence(False)
    stimulus.watch(False)
    audio.wait_log(lambda log: "play:farewell" in log, what="farewell after garbage")
    assert proc.alive()
    assert all(math.isfinite(c.yaw) and math.isfinite(c.pitch) for c in control.messages)
    assert bad_stamp not in [c.stamp_ns for c in control.messages]
    assert no_repeats(expressions(expr))


def test_restart_recovers_state_and_does_not_greet_again(spawn, fast_config, stimulus,
                                                          make_audio, watch, probe) -> None:
    expr, _ = watch
    diag: Collector[m.DiagnosticStatus] = Collector(probe, keys.DIAGNOSTICS, node="controller")
    audio = make_audio(durations={"greeting": 0.3})
    first = start_controller(spawn, fast_config, expr)
    stimulus.presence(True)
    stimulus.watch(True)
    audio.wait_log(lambda log: "end:greeting" in log)
    wait_expressions(expr, [X.EYE_AWAKE])
    first.kill()  # SIGKILL: no goodbye, no clean-up
    expr.clear()
    diag.clear()
    spawn("controller", "--config", str(fast_config))
    # The new process reads the latched presence and sound status: it knows the
    # visitor (engaged, greeted) without greeting again, and re-publishes EYE_AWAKE
    # (the old latched value died with the old process's publisher cache).
    diag.wait_for(lambda d: d.values.get("phase") == "engaged" and d.values.get("greeted")
                  and d.values.get("recovering") is False, timeout=20, what="recovered state")
    n = len(diag.messages)
    diag.wait_count(n + 1, timeout=10)  # one more period (2 s) past the 0.5 s dwell
    assert audio.sounds() == ["greeting"]
    assert expressions(expr) == [X.EYE_AWAKE]
    stimulus.presence(False)
    stimulus.watch(False)
    audio.wait_log(lambda log: "play:farewell" in log, what="farewell after restart")
    seq = wait_expressions(expr, [X.EYE_SLEEPY, X.EYE_SLEEP])
    assert audio.sounds() == ["greeting", "farewell"]
    assert seq == [X.EYE_AWAKE, X.EYE_SLEEPY, X.EYE_SLEEP]


def test_bad_config_is_refused_with_the_key_named(spawn, tmp_path) -> None:
    config = tmp_path / "bad.toml"
    config.write_text("[controller]\nsleepy_s = -2.0\n")
    proc = spawn("controller", "--config", str(config))
    retry_until(lambda: not proc.alive(), 20, what="controller exit")
    assert proc.proc.returncode == 2
    assert "sleepy_s" in proc.output()


def _probe_config(endpoint: str) -> zenoh.Config:
    from buddybot.runtime.node import zenoh_config

    return zenoh_config(connect=[endpoint])


def test_follows_the_configured_camera_only(spawn, fast_config, stimulus, watch,
                                            node_factory) -> None:
    expr, control = watch
    spawn("controller", "--config", str(fast_config), "--camera", "side")
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, timeout=20, what="initial EYE_SLEEP")
    side = node_factory("side-camera").publisher(keys.FACE, camera="side")
    front_stamp = stimulus.face()  # camera "front": not followed
    side_stamp = front_stamp + 1
    side.put(m.FacePosition(stamp_ns=side_stamp, frame_id="side",
                            point=m.Point(x=1.0, y=0.0, z=-0.1), confidence=0.8))
    msg = control.wait_for(lambda c: c.stamp_ns == side_stamp, what="eye control from camera side")
    assert msg.pitch == pytest.approx(0.0)  # z -0.1 + 0.1 camera height = level
    assert front_stamp not in [c.stamp_ns for c in control.messages]


def test_a_face_stamped_in_the_future_never_freezes_the_gaze(spawn, fast_config, stimulus,
                                                             watch) -> None:
    """One face stamped 2**63-1 (or 15 s ahead) must not hold back later faces, and
    no eye control may carry an implausible stamp."""
    expr, control = watch
    spawn("controller", "--config", str(fast_config))
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, timeout=20, what="initial EYE_SLEEP")
    for future in (2**63 - 1, m.now_ns() + 15 * 10**9):
        control.clear()
        stimulus.face(stamp_ns=future)
        control.wait_for(what="eye control of the future-stamped face")
    stamp = stimulus.face()
    control.wait_for(lambda c: c.stamp_ns == stamp, what="gaze still following")
    assert all(c.stamp_ns <= m.now_ns() for c in control.messages)
