"""The radar board as a host of its own: a network namespace this test makes.

A veth pair joins a fresh namespace ("the radar board") to this one ("the robot
computer") on a private /30; the router listens there with TLS + access control.
This checks what loopback cannot: the router certificate must name the address the
board dials (`verify_name_on_connect`), and a board with the right certificate
publishes radar frames from "another machine". Skipped where namespaces cannot be
made (not root, no `ip`, a container without CAP_NET_ADMIN).
"""

from __future__ import annotations

import socket
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Collector,
    Process,
    buddybot_argv,
    free_port,
    retry_until,
    wait_port,
)
from tests.conftest import TIMING
from tests.deploy.conftest import HostProfile, Namespace, make_certs, veth_namespace

pytestmark = [pytest.mark.integration, TIMING]  # network namespaces


@pytest.fixture
def board_ns() -> Iterator[Namespace]:
    with veth_namespace("bbrb") as ns:
        yield ns


@pytest.fixture
def netns_profile(board_ns: Namespace, tmp_path: Path) -> HostProfile:
    """Certificates whose router certificate names the veth address."""
    certs = tmp_path / "certs"
    done = make_certs(certs, board_ns.host_addr)
    assert done.returncode == 0, done.stderr
    work = tmp_path / "zenoh"
    work.mkdir()
    return HostProfile(certs, work)



def test_radar_board_in_its_own_namespace(
    board_ns: Namespace, netns_profile: HostProfile, started: Callable[..., Process],
    tmp_path: Path
) -> None:
    port = free_port()
    board_endpoint = f"tls/{board_ns.host_addr}:{port}"
    local_port = free_port()
    local_endpoint = f"tls/127.0.0.1:{local_port}"
    started(buddybot_argv("router", "--listen", board_endpoint, "--listen", local_endpoint,
                          "--zenoh-config", netns_profile.zenoh_file("router")), "router")
    wait_port(local_port)

    watcher = Node("watcher", connect=[local_endpoint],
                   zenoh_config_file=netns_profile.zenoh_file("operator"))
    try:
        frames = Collector[m.LD2410TargetDataFrameArray](watcher, keys.RADAR_FRAMES, device="*")
        board_config = netns_profile.toml("radar-board", board_endpoint)
        started(board_ns.exec_argv(
                    *buddybot_argv("run", "radar-bridge", "--sim", "--device-id", "3",
                                   "--config", str(board_config))), "radar-board")
        got = frames.wait_for(lambda f: f.device_id == 3, timeout=60,
                              what="frames from the namespaced radar board")
        assert got.sensors
    finally:
        watcher.close()


def test_board_refuses_a_router_not_named_in_its_certificate(
    board_ns: Namespace, cert_dir: Path, started: Callable[..., Process], tmp_path: Path
) -> None:
    """With the session's certificates (router named only localhost/127.0.0.1), the board
    dialling the veth address must refuse the router: it cannot prove that name."""
    profile = HostProfile(cert_dir, tmp_path)
    port = free_port()
    endpoint = f"tls/{board_ns.host_addr}:{port}"
    started(buddybot_argv("router", "--listen", endpoint,
                          "--zenoh-config", profile.zenoh_file("router")), "router")

    def listening() -> bool:
        with socket.create_connection((board_ns.host_addr, port), timeout=0.5):
            return True

    retry_until(listening, 15, what="router on the veth address")
    probe = (
        "import sys, zenoh\n"
        "from buddybot.runtime.node import zenoh_config\n"
        "c = zenoh_config(connect=[sys.argv[1]], base_file=sys.argv[2])\n"
        "c.insert_json5('connect/timeout_ms', '3000')\n"
        "try:\n"
        "    zenoh.open(c).close()\n"
        "    print('CONNECTED')\n"
        "except zenoh.ZError as exc:\n"
        "    print('REFUSED', exc)\n"
    )
    def dial(zenoh_file: str) -> str:
        done = subprocess.run(["ip", "netns", "exec", board_ns.name, sys.executable, "-c", probe,
                               endpoint, zenoh_file], capture_output=True, text=True,
                              timeout=60, check=False)
        return done.stdout + done.stderr

    out = dial(profile.zenoh_file("radar-board"))
    assert "REFUSED" in out, out
    # Positive control: the same board, told not to check the name, gets through, so
    # the refusal above was the name check and not the network.
    lax = Path(profile.zenoh_file("radar-board"))
    lax_text = lax.read_text().replace("verify_name_on_connect: true",
                                       "verify_name_on_connect: false")
    lax_file = tmp_path / "lax.json5"
    lax_file.write_text(lax_text)
    assert "CONNECTED" in dial(str(lax_file))
