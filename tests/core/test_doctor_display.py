"""Doctor's displays check follows the deployment (issue 13): the eye-renderer
that is alive on the bus says where it serves; one that runs on another host
is a warning here, not a failure."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from buddybot.runtime.config import parse_config
from buddybot.runtime.node import Node
from buddybot.tools import doctor
from buddybot.tools.doctor import FAIL, WARN, Check
from buddybot.tools.testing import Process, buddybot_argv, free_port, retry_until

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
