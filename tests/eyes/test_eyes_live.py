"""`buddybot param set eyes ...`: the pupil and the lids change while the driver runs."""

from __future__ import annotations

import subprocess
from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until

pytestmark = pytest.mark.integration

A = m.ExpressionAction


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_unknown_distance_pupil_and_lids_are_live(spawn: Callable[..., Process], probe: Node,
                                                  endpoint: str) -> None:
    eyes = spawn("eyes")
    pupils = Collector[m.PupilControl](probe, keys.PUPIL)
    lids = Collector[m.EyeLidControl](probe, keys.LIDS)
    pub = probe.publisher(keys.EYE_CONTROL)
    stamp = m.now_ns()

    def pupil_for(stamp_ns: int) -> float:
        control = m.EyeControl(stamp_ns=stamp_ns, yaw=0.0, pitch=0.0, target_distance_cm=0)
        retry_until(lambda: pub.put(control) or any(p.stamp_ns == stamp_ns
                                                    for p in pupils.messages),
                    20, 0.2, "driver answering")
        return float(pupils.wait_for(lambda p: p.stamp_ns == stamp_ns).dilation_percentage)

    assert pupil_for(stamp) == pytest.approx(50.0)  # the default for "no distance"
    result = param(endpoint, "set", "eyes", "unknown_distance_percent", "80")
    assert result.returncode == 0, result.stderr
    assert pupil_for(stamp + 1) == pytest.approx(80.0)

    probe.publisher(keys.EXPRESSION).put(m.ScreenExpression(stamp_ns=stamp, action=A.EYE_SAD))
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
