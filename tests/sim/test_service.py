"""The sim service puts the world's truth on `sim/world`; `buddybot sim list|check`."""

from __future__ import annotations

import math
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sim import scenario
from buddybot.tools.testing import Collector, Process, buddybot_argv

Spawn = Callable[..., Process]


def sim_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("sim", *args), capture_output=True, text=True,
                          timeout=120)


@pytest.mark.integration
def test_the_truth_is_the_world_at_the_shared_start(spawn: Spawn, probe: Node) -> None:
    truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
    start = time.time() - 10.0  # the scenario began 10 s ago: the visitor stands at 1 m
    spawn("sim", "--scenario", "visit", "--sim-start", f"{start:.3f}", "--seed", "4")
    first = truth.wait_for(lambda w: bool(w.people), 60, "a person in the world")
    assert first.scenario == "visit" and 10.0 <= first.t_s < 60.0 and first.lap == 0
    person = first.people[0]
    assert person.face == "collins" and person.in_radar and person.in_camera
    assert person.distance_m == pytest.approx(1.0, abs=0.05)
    assert abs(math.remainder(person.facing_rad - math.pi - person.bearing_rad, math.tau)) < 0.1
    later = truth.wait_for(lambda w: w.t_s > first.t_s + 0.5, 30, "time passing")
    assert later.stamp_ns > first.stamp_ns


@pytest.mark.integration
def test_a_bad_scenario_stops_the_service_with_the_key_and_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('description = "x"\nlength_s = -1\n')
    for service in ("sim", "camera", "radar-bridge"):
        out = subprocess.run(buddybot_argv("run", service, "--sim", "--scenario", str(bad),
                                           "--connect", "tcp/127.0.0.1:1")
                             if service != "sim" else
                             buddybot_argv("run", service, "--scenario", str(bad),
                                           "--connect", "tcp/127.0.0.1:1"),
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 2, (service, out.stderr)
        assert "line 2, key 'length_s'" in out.stderr, (service, out.stderr)


@pytest.mark.integration
def test_sim_list_names_every_built_in_scenario_with_what_happens() -> None:
    out = sim_cli("list")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert [line.split()[0] for line in lines] == scenario.builtin_names()
    assert any("loops every 40 s" in line for line in lines if line.startswith("visit"))


@pytest.mark.integration
def test_sim_check_says_ok_or_names_the_key_and_line(tmp_path: Path) -> None:
    ok = sim_cli("check", "two_people")
    assert ok.returncode == 0 and "ok: 2 people" in ok.stdout, ok.stderr
    bad = tmp_path / "mine.toml"
    bad.write_text('description = "x"\nlength_s = 5\n[[person]]\nface = "collins"\n'
                   'path = [{ t = 0, x = 1, y = 0, facing = "sideways" }]\n')
    out = sim_cli("check", str(bad))
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0
    assert "mine.toml, line 5, key 'person[0].path[0].facing'" in out.stderr
    assert sim_cli("check", "party").returncode == 2
    assert sim_cli("check").returncode == 2  # no operand: usage
