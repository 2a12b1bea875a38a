"""`buddybot router` on a port that is already taken: one line naming the endpoint
and who holds it, exit 1, no traceback."""

from __future__ import annotations

import os
import socket
import subprocess

import pytest

from buddybot.runtime import endpoints
from buddybot.runtime.node import Node
from buddybot.tools import doctor
from buddybot.tools.testing import LOOPBACK, buddybot_argv


def run_router(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("router", *args), capture_output=True, text=True,
                          timeout=60)


@pytest.mark.integration
def test_a_plain_listener_on_the_port_is_named_in_one_line() -> None:
    with socket.socket() as holder:
        holder.bind((LOOPBACK, 0))
        holder.listen()
        endpoint = f"tcp/{LOOPBACK}:{holder.getsockname()[1]}"
        result = run_router("--listen", endpoint)
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    line = lines[0]
    assert line.startswith(f"buddybot router: cannot listen on {endpoint}: the port is taken")
    assert "not a Zenoh router" in line
    # The holder is this very test process: psutil can tell (same user).
    assert f"pid {os.getpid()}" in line


@pytest.mark.integration
def test_a_running_router_on_the_port_is_named_with_its_nodes(endpoint: str,
                                                               probe: Node) -> None:
    result = run_router("--listen", endpoint)
    assert result.returncode == 1, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert f"cannot listen on {endpoint}: the port is taken by a Zenoh router" in lines[0]


def test_the_holder_is_found_by_psutil() -> None:
    with socket.socket() as holder:
        holder.bind((LOOPBACK, 0))
        holder.listen()
        port = holder.getsockname()[1]
        found = endpoints.port_holder(f"tcp/{LOOPBACK}:{port}")
    assert found is not None and found.endswith(f"pid {os.getpid()}")
    assert endpoints.port_holder(f"tcp/{LOOPBACK}:{port}") is None  # closed: nobody
    assert doctor.describe_holder(None, "x, pid 1") == ("something that is not a Zenoh "
                                                         "router, process x, pid 1")
    assert doctor.describe_holder(["buddy/camera"]) == ("a Zenoh router (live nodes: "
                                                        "buddy/camera)")
