"""`up` checks the web ports it will listen on before starting anything: the plan
and the texts without processes, the bind check on a real socket, and `up` itself
refusing a taken eye port in one line (exit 2) with nothing started."""

from __future__ import annotations

import argparse
import contextlib
import os
import socket
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from buddybot.runtime.config import default_config, parse_config
from buddybot.supervisor import ports
from buddybot.supervisor.ports import WebPort
from buddybot.tools.testing import Process, buddybot_argv, free_port, retry_until

WEB = ["eye-renderer", "dashboard", "foxglove"]


def _args(**given: object) -> argparse.Namespace:
    return argparse.Namespace(**{"eye_port": None, "dashboard_port": None, **given})


def test_the_planned_ports_follow_the_config_and_the_options() -> None:
    planned = ports.planned_ports(default_config(), _args(), WEB)
    assert [(p.service, p.host, p.port) for p in planned] == [
        ("eye-renderer", "127.0.0.1", 8080), ("dashboard", "127.0.0.1", 8090),
        ("foxglove", "127.0.0.1", 8765)]
    assert planned[0].setting == "[eye_renderer] port or --eye-port"
    assert planned[2].setting == "[foxglove] port"
    moved = ports.planned_ports(default_config(), _args(eye_port=9000, dashboard_port=9001),
                                ["eye-renderer", "dashboard"])
    assert [p.port for p in moved] == [9000, 9001]
    any_free = parse_config(b"[eye_renderer]\nport = 0\n", "robot.toml")
    assert ports.planned_ports(any_free, _args(), ["eye-renderer"]) == []
    assert ports.planned_ports(default_config(), _args(), ["camera", "controller"]) == []


def test_two_services_on_one_port_are_refused() -> None:
    same = parse_config(b"[dashboard]\nport = 8080\n", "robot.toml")
    line = ports.clash(ports.planned_ports(same, _args(), WEB))
    assert line is not None and "eye-renderer and dashboard" in line and "8080" in line
    assert "[dashboard] port" in line
    assert ports.clash(ports.planned_ports(default_config(), _args(), WEB)) is None


def test_the_refusal_names_port_holder_and_setting() -> None:
    wp = WebPort("eye-renderer", "127.0.0.1", 8080, "[eye_renderer] port or --eye-port")
    line = ports.taken_message(wp, "python3, pid 42")
    assert line == ("buddybot up: port 127.0.0.1:8080 of the eye-renderer is taken by "
                    "python3, pid 42: stop it, or change [eye_renderer] port or --eye-port. "
                    "Nothing started.")
    assert "taken:" in ports.taken_message(wp, None)
    assert "0.0.0.0:8080" in ports.taken_message(WebPort("eye-renderer", "", 8080, "x"), None)


def test_an_address_is_printed_only_from_the_services_own_serving_line() -> None:
    assert ports.served_address(
        "eye-renderer", "eye renderer serving http://127.0.0.1:8080/eyes?eye=both") == \
        "eyes: http://127.0.0.1:8080/eyes?eye=both"
    assert ports.served_address(
        "dashboard", "dashboard serving http://127.0.0.1:8090/ (login required)") == \
        "dashboard: http://127.0.0.1:8090/"
    assert ports.served_address("foxglove", "foxglove bridge serving ws://127.0.0.1:8765") \
        == "foxglove: ws://127.0.0.1:8765"
    assert ports.served_address(
        "eye-renderer", "buddybot eye-renderer: cannot serve on 127.0.0.1:8080: the port is "
        "taken") is None
    assert ports.served_address("camera", "serving http://x/") is None


@pytest.fixture
def listener() -> Iterator[socket.socket]:
    """A socket of this test listening on a free loopback port."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(4)
        yield sock


def test_a_listening_port_is_found_taken_with_its_process(listener: socket.socket) -> None:
    port = listener.getsockname()[1]
    assert ports.bind_error("127.0.0.1", port) is not None
    wp = WebPort("eye-renderer", "127.0.0.1", port, "[eye_renderer] port or --eye-port")
    line = ports.first_taken([wp])
    assert line is not None and f"127.0.0.1:{port}" in line
    assert f"pid {os.getpid()}" in line and psutil.Process().name() in line
    free = free_port()
    assert ports.bind_error("127.0.0.1", free) is None
    assert ports.first_taken([WebPort("dashboard", "127.0.0.1", free, "x")]) is None


@pytest.mark.integration
def test_up_refuses_a_taken_eye_port_before_starting_anything(
        listener: socket.socket, tmp_path: Path) -> None:
    port = listener.getsockname()[1]
    config = tmp_path / "robot.toml"
    config.write_text(f"[eye_renderer]\nport = {port}\n")
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(config),
                               "--listen", f"tcp/127.0.0.1:{free_port()}",
                               "--only", "eye-renderer", "--only", "radar-presence"),
                 "up-eye-port", tmp_path)
    started: set[int] = set()
    try:
        def exited() -> bool:
            with contextlib.suppress(psutil.Error):
                started.update(p.pid for p in psutil.Process(up.pid).children(recursive=True))
            return not up.alive()

        retry_until(exited, 60, 0.02, "up refusing")
    finally:
        up.stop()
    out = up.output()
    assert up.proc.returncode == 2, out
    refusals = [x for x in out.splitlines() if "is taken" in x]
    assert len(refusals) == 1, out
    assert f"127.0.0.1:{port}" in refusals[0] and f"pid {os.getpid()}" in refusals[0]
    assert "[eye_renderer] port or --eye-port" in refusals[0]
    assert "Nothing started" in refusals[0]
    assert "eyes:" not in out and "starting router" not in out, out
    assert not started, started
