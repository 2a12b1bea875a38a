"""`buddybot doctor`'s checks on crafted inputs (no robot, no processes), and its displays
check following the deployment: the eye-renderer that is alive on the bus says where it
serves; one that runs on another host is a warning here, not a failure."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from buddybot.runtime import registry
from buddybot.runtime.config import default_config, parse_config
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node
from buddybot.tools import doctor
from buddybot.tools.doctor import FAIL, OK, WARN, Check
from buddybot.tools.testing import Process, buddybot_argv, free_port, retry_until


def test_report_is_one_line_per_check_and_a_summary() -> None:
    checks = [Check("router", OK, "reachable"), Check("nodes", FAIL, "missing: camera"),
              Check("audio device", WARN, "null backend")]
    text = doctor.format_report(checks)
    lines = text.splitlines()
    assert len(lines) == 4
    assert lines[0].split() == ["OK", "router", "reachable"]
    assert lines[1].startswith("FAIL  nodes ") and lines[1].endswith("missing: camera")
    assert lines[3] == ("doctor: 1 ok, 1 warn, 1 fail: nodes (FAIL), audio device (WARN)")
    assert doctor.exit_code(checks) == 1
    assert doctor.exit_code(checks[::2]) == 0  # warnings are not failures
    data = json.loads(doctor.to_json(checks))
    assert data["ok"] is False
    assert data["checks"][1] == {"name": "nodes", "level": "FAIL", "detail": "missing: camera"}


def test_config_error_is_reported_with_its_line() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(b"[camera]\nfps = -3\n", "robot.toml")
    check = doctor.judge_config(None, str(caught.value))
    assert check.level == FAIL and "robot.toml" in check.detail and "fps" in check.detail
    assert doctor.judge_config(default_config(), None).level == OK


def test_nodes_missing_fail_duplicates_warn() -> None:
    live = {"camera": {"a"}, "eyes": {"b", "c"}, "extra": {"d"}}
    missing = doctor.judge_nodes(["camera", "controller"], live)
    assert missing.level == FAIL and missing.detail == "1/2 alive; missing: controller"
    dupes = doctor.judge_nodes(["camera", "eyes"], live)
    assert dupes.level == WARN and "eyes" in dupes.detail
    assert doctor.judge_nodes(["camera"], live).level == WARN  # any duplicate is suspect
    fine = doctor.judge_nodes(["camera"], {"camera": {"a"}, "extra": {"d"}})
    assert fine.level == OK and fine.detail == "1/1 alive (also: extra)"


def test_rates_against_what_is_expected() -> None:
    assert doctor.judge_rate("radar frames", 20, 2.0, 10.0).level == OK
    slow = doctor.judge_rate("camera images", 10, 2.0, 30.0)
    assert slow.level == WARN and "5.0 Hz" in slow.detail
    silent = doctor.judge_rate("camera images", 0, 2.0, 30.0)
    assert silent.level == FAIL and "nothing received" in silent.detail


def test_clock() -> None:
    now = 1_800_000_000.0
    assert doctor.judge_clock(now, 5.0, 5.1).level == OK
    assert doctor.judge_clock(1_500_000_000.0, 5.0, 5.1).level == FAIL  # 2017: never set
    assert doctor.judge_clock(now, 5.0, 4.9).level == FAIL
    near = doctor.judge_clock(now, 5.0, 5.1, stamp_ns=int((now - 0.05) * 1e9))
    assert near.level == OK and "+50 ms" in near.detail
    skewed = doctor.judge_clock(now, 5.0, 5.1, stamp_ns=int((now - 30) * 1e9))
    assert skewed.level == WARN and "+30.0 s" in skewed.detail


def test_router_and_port_verdicts() -> None:
    ok = doctor.judge_router("tls/127.0.0.1:7447", True)
    assert ok.level == OK and "transport tls" in ok.detail
    down = doctor.judge_router("tcp/127.0.0.1:7447", False, "no router. Retry in 500ms.")
    assert down.level == FAIL and down.detail.endswith("no router")
    assert doctor.judge_port("tcp/127.0.0.1:7447", False, None).level == OK
    stranger = doctor.judge_port("tcp/127.0.0.1:7447", True, None)
    assert stranger.level == FAIL and "not a Zenoh router" in stranger.detail
    ours = doctor.judge_port("tcp/127.0.0.1:7447", True, ["buddy/camera"])
    assert ours.level == OK and "buddy/camera" in ours.detail


def test_versions_name_what_is_missing() -> None:
    found = doctor.versions()
    assert found["python"] and found["zenoh"] and found["msgspec"]
    check = doctor.judge_versions({"python": "3.11.7", "ai-edge-litert": None})
    assert check.level == WARN and "ai-edge-litert MISSING" in check.detail


def test_display_down_is_a_failure_not_a_hang() -> None:
    with socket.socket() as holder:  # a port we know nobody serves: bound, not listening
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        check = doctor.check_display("0.0.0.0", port, timeout=1.0)
    assert check.level == FAIL and f"http://127.0.0.1:{port}/healthz" in check.detail


def test_quick_checks_need_no_robot() -> None:
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        opts = doctor.Options(sim=True, endpoint=f"tcp/127.0.0.1:{port}")
        checks = doctor.quick_checks(default_config(), None, opts)
    names = [c.name for c in checks]
    assert names[0] == "config" and "versions" in names and names[-1] == "router port"
    assert checks[-1].level == OK and "is free" in checks[-1].detail
    broken = doctor.quick_checks(None, "robot.toml: bad", opts, port=False)
    assert broken[0] == Check("config", FAIL, "robot.toml: bad")


def test_the_services_lend_their_checks_in_the_registry_order() -> None:
    """Radar, camera and audio checks come from their areas, in the report's order."""
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        opts = doctor.Options(sim=True, endpoint=f"tcp/127.0.0.1:{holder.getsockname()[1]}")
        checks = doctor.quick_checks(default_config(), None, opts)
    assert [c.name for c in checks] == ["config", "radar serial", "camera device",
                                        "audio device", "versions", "router port"]
    assert list(doctor.versions()) == ["python", "buddybot", "zenoh", "msgspec", "numpy",
                                       "opencv", "ai-edge-litert"]
    assert "opencv" in checks[4].detail and "ai-edge-litert" in checks[4].detail


# --- what the robot runs: no alarm for what it was never meant to run ----------------

HARDWARE = b'[radar_bridge]\nsensors = ["/dev/ttyUSB0"]\n[camera]\nsource = "/dev/video0"\n'


def test_services_the_config_does_not_enable_are_not_expected() -> None:
    """foxglove, identity and ros2-bridge run on request: not "missing" when off."""
    expected = doctor.expected_nodes(default_config(), registry.SERVICES, sim=True)
    assert not {"foxglove", "identity", "ros2-bridge"} & set(expected), expected
    assert {"radar-bridge", "camera", "eye-renderer", "dashboard", "sim"} <= set(expected)
    check = doctor.judge_nodes(expected, {name: {"x"} for name in expected})
    assert check.level == OK and f"{len(expected)}/{len(expected)} alive" in check.detail


def test_a_service_the_config_enables_is_expected() -> None:
    config = parse_config(b"[identity]\nenabled = true\n[ros2]\nenabled = true\n",
                          "robot.toml")
    expected = doctor.expected_nodes(config, registry.SERVICES, sim=True)
    assert {"identity", "ros2-bridge"} <= set(expected)
    assert "foxglove" not in expected


def test_the_simulated_world_is_expected_only_when_a_sensor_is_simulated() -> None:
    hardware = parse_config(HARDWARE, "robot.toml")
    assert "sim" not in doctor.expected_nodes(hardware, registry.SERVICES, sim=False)
    assert "sim" in doctor.expected_nodes(hardware, registry.SERVICES, sim=True)


def test_the_configured_apps_are_expected() -> None:
    config = parse_config(b'[apps]\nrun = ["examples/apps/greeter.py"]\n', "robot.toml")
    assert "greeter" in doctor.expected_nodes(config, registry.SERVICES, sim=True)


def test_an_ld2450_robot_is_not_asked_for_radar_frames() -> None:
    """An LD2450 publishes `targets`: no "radar frames: nothing received" for it."""
    angle = parse_config(b'[radar_bridge]\nsensors = ["/dev/ttyUSB0"]\n'
                         b'models = {0 = "LD2450"}\n', "robot.toml")
    names = [r.name for r in doctor.expected_rates(angle, ["radar-bridge"], sim=False)]
    assert names == ["radar targets"]
    simulated = parse_config(b'[radar_bridge]\nsim_model = "LD2450"\n', "robot.toml")
    assert [r.name for r in doctor.expected_rates(simulated, ["radar-bridge"], sim=True)] \
        == ["radar targets"]
    assert [r.name for r in doctor.expected_rates(default_config(), ["radar-bridge"], True)] \
        == ["radar frames"]
    assert doctor.expected_rates(angle, ["camera"], sim=False)[0].name == "camera images"


# --- the displays check follows the deployment ------------------------------------------

HERE = "robot-a"


def plan(*, alive: bool = False, values: dict[str, Any] | None = None, host: str = "127.0.0.1",
         port: int = 8080, expected: bool = True, local: bool = True
         ) -> tuple[str, str] | Check | None:
    return doctor.plan_display(alive=alive, values=values, config_host=host, config_port=port,
                               expected=expected, hostname=HERE, local=local)


def served(url: str, listen: str, hostname: str) -> dict[str, Any]:
    return {"url": url, "listen_host": listen, "hostname": hostname, "pages": 2}


def test_an_alive_renderer_on_this_host_is_checked_where_it_says() -> None:
    # It serves on 9000 although this host's config says 8080: its word wins.
    got = plan(alive=True, values=served("http://127.0.0.1:9000", "0.0.0.0", HERE))
    assert got == ("http://127.0.0.1:9000", "eye-renderer on this host")


def test_an_alive_renderer_on_another_host_is_checked_there() -> None:
    every = plan(alive=True, values=served("http://127.0.0.1:8080", "0.0.0.0", "eyes-pi"),
                 local=False)
    assert every == ("http://eyes-pi:8080", "eye-renderer on eyes-pi")
    bound = plan(alive=True, values=served("http://192.168.1.7:8081", "192.168.1.7", "eyes-pi"))
    assert bound == ("http://192.168.1.7:8081", "eye-renderer on eyes-pi")
    v6 = plan(alive=True, values=served("http://[fd00::7]:8081", "fd00::7", "eyes-pi"))
    assert v6 == ("http://[fd00::7]:8081", "eye-renderer on eyes-pi")
    loopback = plan(alive=True, values=served("http://127.0.0.1:8080", "127.0.0.1", "eyes-pi"))
    assert isinstance(loopback, Check) and loopback.level == WARN
    assert "eyes-pi" in loopback.detail and "only its own loopback" in loopback.detail


def test_an_alive_renderer_that_says_nothing_falls_back_on_the_config() -> None:
    fallback = "eye-renderer did not say where it serves: the config's address"
    assert plan(alive=True, values=None, host="0.0.0.0") == ("http://127.0.0.1:8080", fallback)
    assert plan(alive=True, values={"pages": 0}, host="eyes.local") == (
        "http://eyes.local:8080", fallback)
    unknown = plan(alive=True, values=None, port=0)
    assert isinstance(unknown, Check) and unknown.level == WARN and "port is 0" in unknown.detail


def test_not_running_here_is_a_warning_when_the_config_puts_it_elsewhere() -> None:
    for expected in (True, False):
        away = plan(alive=False, host="192.168.1.7", local=False, expected=expected)
        assert isinstance(away, Check) and away.level == WARN
        assert away.detail.startswith("eye-renderer not running here")
        assert "http://192.168.1.7:8080" in away.detail


def test_not_running_but_expected_here_is_looked_for_at_the_config_address() -> None:
    assert plan(alive=False, host="0.0.0.0") == ("http://127.0.0.1:8080",
                                                 "the config's address")
    assert plan(alive=False, expected=False) is None  # not asked about: no check


def test_which_hosts_are_this_machine() -> None:
    names, addresses = {"robot-a", "robot-a.local", "localhost"}, {"192.168.1.5", "fe80::1"}
    for host in ("", "0.0.0.0", "::", "127.0.0.1", "127.1.2.3", "::1", "localhost",
                 "Robot-A", "robot-a.local.", "192.168.1.5", "[fe80::1]"):
        assert doctor.is_local_host(host, names, addresses), host
    for host in ("192.168.1.7", "eyes-pi", "eyes-pi.local", "fd00::7"):
        assert not doctor.is_local_host(host, names, addresses), host
    assert "localhost" in doctor.own_names()
    assert "127.0.0.1" in doctor.own_addresses()


def test_the_eye_renderer_is_not_expected_here_when_the_config_puts_it_elsewhere() -> None:
    names = ["radar-bridge", "eye-renderer", "eyes"]
    away = parse_config(b'[eye_renderer]\nhost = "192.0.2.10"\n', "robot.toml")
    here = parse_config(b'[eye_renderer]\nhost = "0.0.0.0"\n', "robot.toml")
    assert doctor.expected_here(names, away) == ["radar-bridge", "eyes"]
    assert doctor.expected_here(names, here) == names
    assert doctor.expected_here(names, None) == names


def test_a_plan_is_looked_at_and_a_dead_url_fails() -> None:
    with socket.socket() as holder:  # bound, not listening: nobody serves there
        holder.bind(("127.0.0.1", 0))
        port = holder.getsockname()[1]
        check = doctor.check_display_url(f"http://127.0.0.1:{port}", 1.0, "eye-renderer on x")
    assert check.level == FAIL and check.detail.endswith("(eye-renderer on x)")


# --- as processes -------------------------------------------------------------------


def run_doctor(tmp_path: Path, *args: str) -> tuple[int, str]:
    proc = Process(buddybot_argv("doctor", *args), f"doctor-{time.monotonic_ns()}", tmp_path)
    try:
        status = proc.proc.wait(60)
    finally:
        proc.stop()
    return status, proc.output()


def displays_line(out: str) -> str:
    found = [x for x in out.splitlines() if x[6:].startswith("displays ")]
    assert len(found) == 1, out
    return found[0]


@pytest.mark.integration
def test_doctor_follows_the_renderer_not_this_hosts_config(
        tmp_path: Path, endpoint: str, probe: Node, spawn: Callable[..., Process]) -> None:
    served_port, configured_port = free_port(), free_port()
    spawn("eye-renderer", "--no-browser", "--port", str(served_port),
          env={"DISPLAY": "", "WAYLAND_DISPLAY": ""})
    retry_until(lambda: "eye-renderer" in probe.node_instances(timeout=1), 60, 0.2,
                "eye-renderer alive")
    config = tmp_path / "robot.toml"
    config.write_text(f"[eye_renderer]\nport = {configured_port}\n")
    status, out = run_doctor(tmp_path, "--connect", endpoint, "--config", str(config), "--sim",
                             "--expect", "eye-renderer", "--timeout", "5")
    line = displays_line(out)
    assert line.startswith("OK"), out
    assert f"http://127.0.0.1:{served_port}/healthz" in line
    assert "eye-renderer on this host" in line
    assert status == 0, out


@pytest.mark.integration
def test_doctor_warns_when_the_renderer_runs_on_another_host(
        tmp_path: Path, endpoint: str, probe: Node, spawn: Callable[..., Process]) -> None:
    spawn("radar-presence")
    retry_until(lambda: "radar-presence" in probe.node_instances(timeout=1), 60, 0.2,
                "radar-presence alive")
    config = tmp_path / "robot.toml"
    config.write_text('[eye_renderer]\nhost = "192.0.2.10"\nport = 8080\n')  # TEST-NET-1
    status, out = run_doctor(tmp_path, "--connect", endpoint, "--config", str(config), "--sim",
                             "--expect", "radar-presence", "--timeout", "3")
    line = displays_line(out)
    assert line.startswith("WARN") and "eye-renderer not running here" in line, out
    assert "http://192.0.2.10:8080" in line
    assert status == 0, out  # a warning, not a failure


@pytest.mark.integration
def test_doctor_counts_an_ld2450_robots_targets(
        tmp_path: Path, endpoint: str, probe: Node, spawn: Callable[..., Process]) -> None:
    """The false alarm as a user met it: a simulated LD2450 robot, doctor's radar line."""
    spawn("radar-bridge", "--sim", "--sim-model", "LD2450")
    retry_until(lambda: "radar-bridge" in probe.node_instances(timeout=1), 60, 0.2,
                "radar-bridge alive")
    config = tmp_path / "robot.toml"
    config.write_text('[radar_bridge]\nsim_model = "LD2450"\n')
    status, out = run_doctor(tmp_path, "--connect", endpoint, "--config", str(config), "--sim",
                             "--expect", "radar-bridge", "--timeout", "5", "--window", "2")
    assert "radar frames" not in out and "radar reports" not in out, out
    [line] = [x for x in out.splitlines() if x[6:].startswith("radar targets ")]
    assert line.startswith("OK"), out
    assert status == 0, out
