"""The router most tests use, opened in the test's own process
(`testing.InProcessRouter`): the Zenoh router `buddybot router` serves, without
its process. It must carry traffic between processes, be no node of any robot,
and leave its port closed and free when stopped."""

from __future__ import annotations

import json
import socket
from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import endpoints
from buddybot.runtime.node import Node
from buddybot.tools.testing import LOOPBACK, Collector, InProcessRouter, Process, retry_until
from tests.cli.process import bb

pytestmark = pytest.mark.integration


def test_a_service_process_and_a_probe_meet_through_it(
        spawn: Callable[..., Process], node_factory: Callable[..., Node]) -> None:
    """A `buddybot run` process publishes through the router in this process."""
    watcher = node_factory("watcher")
    diag = Collector[m.DiagnosticStatus](watcher, keys.DIAGNOSTICS, node="audio-player")
    spawn("audio-player", "--backend", "null")
    diag.wait_for(timeout=60)
    assert "audio-player" in watcher.node_instances(timeout=5)


def test_it_is_no_node_of_any_robot(endpoint: str, node_factory: Callable[..., Node]) -> None:
    """What `buddybot nodes` counts are the nodes' tokens: the router declares none."""
    node_factory("only-one")
    listed = retry_until(
        lambda: (r := bb("nodes", "--json", "--all-robots", "--connect", endpoint))
        and r.returncode == 0 and json.loads(r.stdout)["nodes"], 30, 0.5, "nodes --json")
    assert set(listed) == {"buddy/only-one"}


def test_stopped_its_port_is_closed_and_free() -> None:
    router = InProcessRouter()
    assert endpoints.accepting(router.endpoint)
    router.stop()
    assert not endpoints.accepting(router.endpoint)
    with socket.socket() as sock:
        # As a server binds (Zenoh's listener too): a connection of the check above
        # may linger in TIME_WAIT on the port; a listener still there fails the bind.
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((LOOPBACK, router.port))  # nothing holds it any more
        sock.listen()
