"""The probing verbs as a new user meets them, as real processes: no router,
the wrong protocol, a wrong key or robot, a refused call, a publish nobody
hears, enum names both ways, and output scripts can parse (issue 13)."""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Collector,
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
)

pytestmark = pytest.mark.integration

FAST_S = 15.0
"""A probe that gives up after 1 s must be done well within this (interpreter
start and Zenoh included), nowhere near "forever"."""


def bb(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv(*args), capture_output=True, text=True, timeout=timeout)


def one_line_error(result: subprocess.CompletedProcess[str]) -> str:
    """The stderr line of a failed probe: exit 1, no traceback."""
    assert result.returncode == 1, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.startswith("buddybot ")]
    assert len(lines) == 1, result.stderr
    return lines[0]


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


def test_echo_without_timeout_says_once_why_nothing_comes(endpoint: str, log_dir: Path) -> None:
    """Running until stopped is what `echo` is for, but not silently."""
    echo = Process(buddybot_argv("echo", "eyes/nothing", "--connect", endpoint), "echo", log_dir)
    try:
        echo.wait_for_output("nothing yet", timeout=30)
        assert "matches no key of the catalogue" in echo.output() and echo.alive()
    finally:
        assert echo.stop() == 0


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


def test_echo_on_a_quiet_known_key_lists_who_is_alive(
        endpoint: str, node_factory: Callable[..., Node]) -> None:
    node_factory("somebody")
    line = retry_until(lambda: (r := bb("echo", "eyes/pupil", "--connect", endpoint,
                                        "--timeout", "1")) and "somebody" in r.stderr
                       and one_line_error(r), 30, 0.5, "echo naming the live node")
    assert "no publisher matches buddybot/buddy/eyes/pupil" in line


# --- calls, publications ---------------------------------------------------------------


def test_a_refused_call_prints_the_reply_and_exits_1(endpoint: str, spawn: Callable[..., Process]
                                                     ) -> None:
    spawn("audio-player", "--backend", "null")
    result = retry_until(
        lambda: (r := bb("call", "audio/pause", "--connect", endpoint, "--timeout", "5"))
        and "no reply" not in r.stderr and r, 60, 0.5, "the player answering")
    line = one_line_error(result)
    assert '"success":false' in result.stdout and "nothing is playing" in result.stdout
    assert "audio/pause refused" in line and "nothing is playing" in line
    ok = bb("call", "audio/stop", "--connect", endpoint, "--timeout", "5")
    assert ok.returncode == 0 and '"success":true' in ok.stdout, ok.stderr


def test_pub_warns_when_nobody_listens_and_not_when_someone_does(
        endpoint: str, node_factory: Callable[..., Node]) -> None:
    alone = bb("pub", "eyes/pupil", '{"dilation_percentage": 5}', "--connect", endpoint,
               "--wait", "0.5")
    assert alone.returncode == 0, alone.stderr
    assert "warning: no subscriber matches buddybot/buddy/eyes/pupil" in alone.stderr
    got = Collector[m.PupilControl](node_factory("listener"), keys.PUPIL)
    heard = bb("pub", "eyes/pupil", '{"dilation_percentage": 6}', "--connect", endpoint)
    assert heard.returncode == 0 and "warning" not in heard.stderr, heard.stderr
    got.wait_for(lambda p: p.dilation_percentage == 6, timeout=10)


# --- enum names, both ways -------------------------------------------------------------


def test_enum_names_round_trip_through_pub_and_echo(
        endpoint: str, node_factory: Callable[..., Node], log_dir: Path) -> None:
    got = Collector[m.ScreenExpression](node_factory("listener"), keys.EXPRESSION)
    result = bb("pub", "eyes/expression", '{"action": "EYE_SLEEP"}', "--connect", endpoint)
    assert result.returncode == 0, result.stderr
    assert got.wait_for(timeout=10).action is m.ExpressionAction.EYE_SLEEP
    talker = Process(buddybot_argv("pub", "eyes/expression", '{"action": "EYE_SLEEP"}',
                                   "--rate", "20", "--connect", endpoint), "talker", log_dir)
    try:
        named = bb("echo", "eyes/expression", "-n", "1", "--timeout", "20", "--connect", endpoint)
        raw = bb("echo", "eyes/expression", "-n", "1", "--timeout", "20", "--raw",
                 "--connect", endpoint)
    finally:
        talker.stop()
    assert named.returncode == 0 and raw.returncode == 0, (named.stderr, raw.stderr)
    assert json.loads(named.stdout)["action"] == "EYE_SLEEP"
    assert json.loads(raw.stdout)["action"] == 1


def test_a_wrong_enum_name_is_a_usage_error_listing_the_names() -> None:
    result = bb("pub", "eyes/expression", '{"action": "EYE_SLEEPING"}',
                "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert result.returncode == 2 and "EYE_SLEEPING" in result.stderr
    assert "EYE_SLEEPY" in result.stderr and "Traceback" not in result.stderr


# --- output for scripts ----------------------------------------------------------------


def test_json_outputs_are_one_document(endpoint: str, node_factory: Callable[..., Node]) -> None:
    node_factory("visible-node")
    nodes = retry_until(
        lambda: (r := bb("nodes", "--json", "--connect", endpoint)) and r.returncode == 0
        and "visible-node" in r.stdout and json.loads(r.stdout), 30, 0.5, "nodes --json")
    assert nodes["robot"] == "buddy" and len(nodes["nodes"]["visible-node"]) == 1
    empty = bb("nodes", "--json", "--robot", "r2", "--connect", endpoint)
    assert empty.returncode == 1 and json.loads(empty.stdout) == {"robot": "r2", "nodes": {}}
    table = json.loads(bb("keys", "--json").stdout)
    assert {row["key"] for row in table} >= {t.pattern for t in keys.TOPICS}
    config = json.loads(bb("config", "--json", "--connect", endpoint, "--robot", "r9").stdout)
    assert config["robot"]["id"] == "r9" and config["zenoh"]["connect"] == [endpoint]


def test_hz_json_reports_the_rate(endpoint: str, log_dir: Path) -> None:
    talker = Process(buddybot_argv("pub", "eyes/pupil", '{"dilation_percentage": 5}',
                                   "--rate", "20", "--connect", endpoint), "talker", log_dir)
    try:
        result = bb("hz", "eyes/pupil", "--json", "--duration", "4", "--connect", endpoint)
    finally:
        talker.stop()
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["key"] == "buddybot/buddy/eyes/pupil" and 10 < report["rate_hz"] < 30
    assert report["received"] >= report["window"] >= 2


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
