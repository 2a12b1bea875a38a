"""`buddybot run eyes` as a real process behind a real router, and its settings changed
live through `buddybot param set eyes ...`."""

from __future__ import annotations

import math
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until

pytestmark = pytest.mark.integration

A = m.ExpressionAction


def test_control_becomes_direction_and_pupil(spawn: Callable[..., Process], probe: Node) -> None:
    spawn("eyes")
    directions = Collector[m.EyesDirection](probe, keys.EYES_DIRECTION)
    pupils = Collector[m.PupilControl](probe, keys.PUPIL)
    pub = probe.publisher(keys.BEHAVIOUR_GAZE)
    # Real stamps: the runtime replaces implausible ones (not near now) by the arrival time.
    now = m.now_ns()
    near = m.EyeControl(stamp_ns=now, yaw=math.radians(20), pitch=math.radians(-10),
                        target_distance_cm=40)
    retry_until(lambda: pub.put(near) or directions.messages, 20, 0.2, "driver answering")
    d = directions.wait_for(lambda x: x.stamp_ns == near.stamp_ns)
    assert d.yaw == pytest.approx(20.0) and d.pitch == pytest.approx(-10.0)
    p_near = pupils.wait_for(lambda x: x.stamp_ns == near.stamp_ns)

    far = m.EyeControl(stamp_ns=now + 1, yaw=math.radians(-35), pitch=0.0,
                       target_distance_cm=280)
    pub.put(far)
    d = directions.wait_for(lambda x: x.stamp_ns == far.stamp_ns)
    assert d.yaw == pytest.approx(-35.0)
    p_far = pupils.wait_for(lambda x: x.stamp_ns == far.stamp_ns)
    assert p_near.dilation_percentage > p_far.dilation_percentage


def test_every_expression_becomes_latched_lids(
    spawn: Callable[..., Process], node_factory: Callable[..., Node]
) -> None:
    spawn("eyes")
    probe = node_factory("probe")
    lids = Collector[m.EyeLidControl](probe, keys.LIDS)
    pub = probe.publisher(keys.BEHAVIOUR_EXPRESSION)
    expected = {A.EYE_AWAKE: (0, 0), A.EYE_SLEEP: (50, 50)}
    base = m.now_ns()
    for stamp, action in enumerate(A, start=base):
        pub.put(m.ScreenExpression(stamp_ns=stamp, action=action))
        got = lids.wait_for(lambda x, s=stamp: x.stamp_ns == s, 20, f"lids for {action.name}")
        assert got.eye_id == m.EyeId.BOTH
        if action in expected:
            assert (got.top_lid_position, got.bottom_lid_position) == expected[action]
    # Latched: a renderer starting now still gets the current lids (the last: STAR).
    late = Collector[m.EyeLidControl](node_factory("late"), keys.LIDS)
    got = late.wait_for(timeout=20, what="latched lids")
    assert got.stamp_ns == base + len(A) - 1


def test_malformed_input_is_survived(spawn: Callable[..., Process], probe: Node) -> None:
    proc = spawn("eyes")
    directions = Collector[m.EyesDirection](probe, keys.EYES_DIRECTION)
    diags = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="eyes")
    control = probe.publisher(keys.BEHAVIOUR_GAZE)
    expression = probe.publisher(keys.BEHAVIOUR_EXPRESSION)
    good = m.EyeControl(stamp_ns=m.now_ns(), yaw=0.1, pitch=0.0, target_distance_cm=100)
    retry_until(lambda: control.put(good) or directions.messages, 20, 0.2, "driver answering")
    for bad in (b"", b"not json", b"{}", b'{"stamp_ns": 1, "yaw": 9, "pitch": 0, '
                b'"target_distance_cm": 1}', b'{"stamp_ns": -1, "yaw": 0, "pitch": 0, '
                b'"target_distance_cm": 1}', b'[1, 2]', b'{"stamp_ns": 1, "yaw": "left", '
                b'"pitch": 0, "target_distance_cm": 1}', b"\xff\xfe" * 100):
        control.put_bytes(bad)
    for bad in (b'{"stamp_ns": 1, "action": 99}', b'{"stamp_ns": 1}', b"\x00"):
        expression.put_bytes(bad)
    after = m.EyeControl(stamp_ns=m.now_ns(), yaw=-0.1, pitch=0.0, target_distance_cm=100)
    control.put(after)
    directions.wait_for(lambda x: x.stamp_ns == after.stamp_ns, 20,
                        "direction after malformed input")
    status = diags.wait_for(lambda x: int(x.values.get("malformed", 0)) >= 11, 20,
                            "malformed count in diagnostics")
    assert status.level == "OK"
    assert proc.alive()
    assert "dropped malformed" in proc.output()


@pytest.mark.parametrize(("toml", "message"), [
    ("[eyes]\npupil_curve = [[100, 20], [50, 40]]\n", "eyes.pupil_curve"),
    ("[eyes]\nlids = { EYE_WINK = [0, 0] }\n", "eyes.lids"),
    ("[eyes]\nunknown_distance_percent = 150\n", "unknown_distance_percent"),
    ("[eyes]\npupil = 3\n", "pupil"),
])
def test_bad_config_exits_with_the_key_named(tmp_path: Path, toml: str, message: str) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(toml)
    proc = Process(buddybot_argv("run", "eyes", "--config", str(cfg),
                                 "--connect", "tcp/127.0.0.1:9"), "eyes-bad", tmp_path)
    try:
        assert proc.proc.wait(30) == 2
        assert message in proc.output()
    finally:
        proc.stop()


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_unknown_distance_pupil_and_lids_are_live(spawn: Callable[..., Process], probe: Node,
                                                  endpoint: str) -> None:
    eyes = spawn("eyes")
    pupils = Collector[m.PupilControl](probe, keys.PUPIL)
    lids = Collector[m.EyeLidControl](probe, keys.LIDS)
    pub = probe.publisher(keys.BEHAVIOUR_GAZE)
    stamp = m.now_ns()

    def pupil() -> float:
        """The pupil for a distance-less control stamped now (an old stamp would be
        replaced by its arrival time, as implausible, after a slow `param set`)."""
        stamp_ns = m.now_ns()
        control = m.EyeControl(stamp_ns=stamp_ns, yaw=0.0, pitch=0.0, target_distance_cm=0)
        retry_until(lambda: pub.put(control) or any(p.stamp_ns == stamp_ns
                                                    for p in pupils.messages),
                    20, 0.2, "driver answering")
        return float(pupils.wait_for(lambda p: p.stamp_ns == stamp_ns).dilation_percentage)

    assert pupil() == pytest.approx(50.0)  # the default for "no distance"
    result = param(endpoint, "set", "eyes", "unknown_distance_percent", "80")
    assert result.returncode == 0, result.stderr
    assert pupil() == pytest.approx(80.0)

    probe.publisher(keys.BEHAVIOUR_EXPRESSION).put(m.ScreenExpression(stamp_ns=stamp,
                                                                      action=A.EYE_SAD))
    lids.wait_for(lambda x: x.eye_id == m.EyeId.BOTH, 20, "lids for EYE_SAD")
    lids.clear()
    result = param(endpoint, "set", "eyes", "lids", '{"EYE_SAD": [33, 7]}')
    assert result.returncode == 0, result.stderr
    # Shown at once for the expression on screen, without a new expression.
    now = lids.wait_for(lambda x: x.top_lid_position == 33.0, 20, "new lids at once")
    assert now.bottom_lid_position == 7.0

    bad = param(endpoint, "set", "eyes", "lids", '{"EYE_SAD": [300, 7]}')
    assert bad.returncode == 1 and "lid positions must be within 0..100" in bad.stderr
    curve = param(endpoint, "set", "eyes", "pupil_curve", "[[100, 20], [50, 60]]")
    assert curve.returncode == 1 and "eyes.pupil_curve" in curve.stderr
    assert eyes.alive()
