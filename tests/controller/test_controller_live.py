"""`buddybot param set controller greet_dwell_s ...` decides the next greeting, no restart."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until

from .conftest import FAST_CONFIG

pytestmark = pytest.mark.integration

X = m.ExpressionAction


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_greeting_dwell_is_live(spawn: Callable[..., Process], probe: Node, stimulus: Any,
                                make_audio: Callable[..., Any], endpoint: str,
                                tmp_path: Path) -> None:
    config = tmp_path / "controller.toml"  # a dwell nobody waits out: never greets
    config.write_text(FAST_CONFIG.replace("greet_dwell_s = 0.5", "greet_dwell_s = 3600.0"))
    audio = make_audio(durations={"greeting": 0.3})
    expr = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="controller")
    proc = spawn("controller", "--config", str(config))
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, 20, "initial EYE_SLEEP")

    stimulus.presence(True)
    stimulus.watch(True)
    engaged = diag.wait_for(lambda d: d.values.get("phase") == "engaged", 20, "engaged")
    diag.wait_for(lambda d: d.stamp_ns > engaged.stamp_ns, 10)  # a whole period engaged
    assert audio.sounds() == []  # 3600 s dwell: no greeting yet

    result = param(endpoint, "set", "controller", "greet_dwell_s", "0.2")
    assert result.returncode == 0, result.stderr
    audio.wait_log(lambda log: "play:greeting" in log, what="greeting after the set")
    retry_until(lambda: "parameters changed: greet_dwell_s=0.2" in proc.output(), 10,
                what="the change logged")
    assert proc.alive()
