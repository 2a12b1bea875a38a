"""What the probing verbs share (`buddybot.tools.probing`), met as real processes: no
router, the wrong protocol, a wrong key or robot, Zenoh's log, a router's access
control. Each verb's own behaviour is tested in tests/cli/test_<verb>.py."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
)
from tests.cli.process import bb, one_line_error

pytestmark = pytest.mark.integration

FAST_S = 15.0
"""A probe that gives up after 1 s must be done well within this (interpreter
start and Zenoh included), nowhere near "forever"."""


# --- no router, wrong router ----------------------------------------------------------

PROBES = [
    ("nodes",),
    ("echo", "eyes/pupil"),
    ("hz", "eyes/pupil"),
    ("pub", "eyes/pupil", '{"dilation_percentage": 5}'),
    ("call", "audio/stop"),
]


@pytest.mark.parametrize("verb", PROBES, ids=[p[0] for p in PROBES])
def test_every_probe_gives_up_on_a_refused_port_saying_why(verb: tuple[str, ...]) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    started = time.monotonic()
    result = bb(*verb, "--connect", endpoint, "--timeout", "1")
    took = time.monotonic() - started
    line = one_line_error(result)
    assert took < FAST_S, f"took {took:.1f} s"
    assert endpoint in line and "Connection refused" in line, line
    assert "gave up after 1 s" in line


def test_the_default_timeout_bounds_the_connection_too() -> None:
    """`echo` without --timeout runs until stopped, but not without a router."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    line = one_line_error(bb("echo", "eyes/pupil", "--connect", endpoint))
    assert time.monotonic() - started < 5 + FAST_S
    assert endpoint in line and "gave up after 5 s" in line


def test_tls_to_a_tcp_router_is_named_as_a_protocol_problem(router: Router) -> None:
    endpoint = f"tls/127.0.0.1:{router.port}"
    line = one_line_error(bb("nodes", "--connect", endpoint, "--timeout", "1"))
    assert endpoint in line and "no Zenoh session follows" in line and "wrong protocol" in line


def test_a_service_still_waits_for_its_router_and_says_why(log_dir: Path) -> None:
    """Only probes give up: `run SERVICE` waits (services start in any order),
    and its periodic warning now carries Zenoh's reason."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    service = Process(buddybot_argv("run", "audio-player", "--backend", "null",
                                    "--connect", endpoint), "waiting-service", log_dir)
    try:
        service.wait_for_output("waiting for the Zenoh router", timeout=30)
        assert service.alive()
        retry_until(lambda: "Connection refused" in service.output(), 30,
                    what="the reason in the waiting line")
        assert service.alive(), service.output()
    finally:
        service.stop()


# --- nothing arrives: say why ----------------------------------------------------------


def test_echo_and_hz_name_an_unknown_key(endpoint: str) -> None:
    for verb in ("echo", "hz"):
        line = one_line_error(bb(verb, "eyes/nothing", "--connect", endpoint, "--timeout", "1"))
        assert "buddybot/buddy/eyes/nothing" in line and "matches no key of the catalogue" in line


def test_echo_and_hz_name_a_robot_without_nodes(endpoint: str,
                                                node_factory: Callable[..., Node]) -> None:
    node_factory("somebody")  # robot buddy is alive; robot r2 is not
    for verb in ("echo", "hz"):
        line = one_line_error(bb(verb, "eyes/pupil", "--robot", "r2", "--connect", endpoint,
                                 "--timeout", "1"))
        assert "no node of robot 'r2' is alive" in line, line
    nodes = bb("nodes", "--robot", "r2", "--connect", endpoint)
    assert "no live node of robot 'r2'" in one_line_error(nodes) and nodes.stdout == ""


# --- calls, publications ---------------------------------------------------------------


# --- enum names, both ways -------------------------------------------------------------


def test_zenoh_log_reaches_our_log_not_stdout(endpoint: str) -> None:
    """Zenoh's own log is routed into ours (stderr); stdout stays pure data."""
    result = bb("nodes", "--json", "--connect", endpoint, "--log-level", "DEBUG")
    assert result.returncode == 1, result.stderr  # no node: still one document
    assert isinstance(json.loads(result.stdout), dict)  # nothing but the document
    assert " zenoh: zenoh::" in result.stderr  # Zenoh's DEBUG lines, in our format
    assert "\x1b[" not in result.stderr  # without its terminal colours


DENY_ALL = """{
  access_control: {enabled: true, default_permission: "deny", rules: [], subjects: [],
                   policies: []},
}
"""


def test_a_router_whose_access_control_denies_the_probe(tmp_path: Path) -> None:
    """Zenoh tells a client nothing when its router's ACL drops its traffic; the
    probe still exits 1, and names access control among the causes."""
    acl = tmp_path / "deny-all.json5"
    acl.write_text(DENY_ALL)
    router = Router(log_dir=tmp_path / "logs", extra=["--zenoh-config", str(acl)])
    try:
        for verb in ("echo", "hz"):
            line = one_line_error(bb(verb, "eyes/pupil", "--connect", router.endpoint,
                                     "--timeout", "1"))
            assert "access control" in line, line
    finally:
        router.stop()
