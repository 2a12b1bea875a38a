"""`buddybot doctor` against a real robot: healthy (exit 0), broken (exit 1 naming
what is wrong), and never hanging on a missing router."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, buddybot_argv, free_port, retry_until


def run_doctor(tmp_path: Path, *args: str, timeout: float = 60.0) -> tuple[int, str, float]:
    """`buddybot doctor ARGS` to its end: (status, output, seconds it took)."""
    t0 = time.monotonic()
    proc = Process(buddybot_argv("doctor", *args), f"doctor-{time.monotonic_ns()}", tmp_path)
    try:
        status = proc.proc.wait(timeout)
    finally:
        proc.stop()
    return status, proc.output(), time.monotonic() - t0


def line_of(out: str, name: str) -> str:
    """The report line of check `name`."""
    found = [x for x in out.splitlines() if x[6:].startswith(name + " ")]
    assert len(found) == 1, out
    return found[0]


@pytest.mark.integration
def test_doctor_on_a_healthy_robot(tmp_path: Path, endpoint: str, probe: Node,
                                   spawn: Callable[..., Process]) -> None:
    eye_port = free_port()
    config = tmp_path / "robot.toml"
    config.write_text(f"[eye_renderer]\nport = {eye_port}\n")
    spawn("radar-bridge", "--sim")
    spawn("radar-presence")
    spawn("eye-renderer", "--no-browser", "--config", str(config))
    expected = ["radar-bridge", "radar-presence", "eye-renderer"]
    retry_until(lambda: set(expected) <= set(probe.node_instances(timeout=1)), 60, 0.2,
                "the three nodes alive")
    args = ["--connect", endpoint, "--config", str(config), "--sim", "--timeout", "5",
            "--window", "2"]
    for name in expected:
        args += ["--expect", name]
    status, out, _ = run_doctor(tmp_path, *args)
    assert status == 0, out
    assert line_of(out, "router").startswith("OK") and "transport tcp" in out
    assert line_of(out, "nodes").startswith("OK") and "3/3 alive" in out
    assert line_of(out, "radar frames").startswith("OK"), out
    assert line_of(out, "displays").startswith("OK"), out
    assert f"127.0.0.1:{eye_port}/healthz" in line_of(out, "displays")
    assert line_of(out, "clock").startswith("OK") and "received stamp" in out
    assert line_of(out, "config").startswith("OK")
    assert out.splitlines()[-1].startswith("doctor: ") and " 0 fail" in out

    status, out, _ = run_doctor(tmp_path, *args, "--json", "--window", "0.5")
    report = json.loads(out[out.index("{"):])
    assert status == 0 and report["ok"] is True
    assert {c["name"] for c in report["checks"]} >= {"router", "nodes", "versions", "clock"}


@pytest.mark.integration
def test_doctor_names_a_missing_node(tmp_path: Path, endpoint: str, probe: Node,
                                     spawn: Callable[..., Process]) -> None:
    spawn("radar-presence")
    retry_until(lambda: "radar-presence" in probe.node_instances(timeout=1), 60, 0.2,
                "radar-presence alive")
    status, out, _ = run_doctor(tmp_path, "--connect", endpoint, "--sim", "--expect",
                                "radar-presence", "--expect", "controller", "--timeout", "5")
    assert status == 1, out
    assert line_of(out, "nodes").startswith("FAIL")
    assert "1/2 alive; missing: controller" in line_of(out, "nodes")
    assert line_of(out, "router").startswith("OK")


@pytest.mark.integration
def test_doctor_without_a_router_fails_fast(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    status, out, took = run_doctor(tmp_path, "--connect", endpoint, "--sim", "--timeout", "1")
    assert status == 1, out
    assert line_of(out, "router").split(None, 2) == [
        "FAIL", "router", f"{endpoint} (transport tcp): nothing listens there (is the "
        "router or `buddybot up` running?)"]
    assert "Traceback" not in out
    assert took < 20, f"doctor took {took:.1f} s with no router"


@pytest.mark.integration
def test_doctor_quick_reports_a_bad_config(tmp_path: Path) -> None:
    config = tmp_path / "robot.toml"
    config.write_text("[camera]\nfps = -3\n")
    status, out, _ = run_doctor(tmp_path, "--quick", "--sim", "--config", str(config),
                                "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert status == 1, out
    line = line_of(out, "config")
    assert line.startswith("FAIL") and str(config) in line and "fps" in line
    assert line_of(out, "router port").startswith("OK")  # the other checks still ran
    assert line_of(out, "versions")


@pytest.mark.integration
def test_doctor_quick_names_who_holds_the_router_port(tmp_path: Path, endpoint: str,
                                                     spawn: Callable[..., Process],
                                                     probe: Node) -> None:
    spawn("radar-presence")
    retry_until(lambda: "radar-presence" in probe.node_instances(timeout=1), 60, 0.2,
                "radar-presence alive")
    status, out, _ = run_doctor(tmp_path, "--quick", "--sim", "--connect", endpoint)
    assert status == 0, out
    line = line_of(out, "router port")
    assert line.startswith("OK") and "a Zenoh router runs there" in line
    assert "buddy/radar-presence" in line
    assert "nodes " not in out  # quick: nothing that needs the running robot
