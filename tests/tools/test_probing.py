"""What the probing verbs share (`buddybot.tools.probing`): enum names in and out, the
catalogue check behind "nothing matches", refusals, Zenoh's log lines and the bounded
connection of a probe; then, met as real processes: no router, the wrong protocol, a wrong
key or robot, Zenoh's log, a router's access control. Each verb's own behaviour is tested
in tests/cli/test_<verb>.py."""

from __future__ import annotations

import argparse
import json
import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest

from buddybot.contract import keys, schemas
from buddybot.contract import messages as m
from buddybot.contract.describe import describe, enum_values, summarize
from buddybot.runtime import session
from buddybot.runtime.config import default_config
from buddybot.runtime.errors import UsageError
from buddybot.runtime.node import Node
from buddybot.runtime.service import ServiceContext
from buddybot.tools import probing
from buddybot.tools.testing import (
    InProcessRouter,
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
)
from tests.cli.process import bb, one_line_error

# --- enum names ---------------------------------------------------------------------


def test_enum_names_and_numbers_are_both_accepted() -> None:
    by_name = probing.parse_message(m.ScreenExpression, '{"action": "EYE_SLEEP", "stamp_ns": 1}')
    by_number = probing.parse_message(m.ScreenExpression, '{"action": 1, "stamp_ns": 1}')
    assert by_name == by_number
    assert isinstance(by_name, m.ScreenExpression)
    assert by_name.action is m.ExpressionAction.EYE_SLEEP


def test_an_unknown_enum_name_is_refused_listing_the_names() -> None:
    with pytest.raises(UsageError) as caught:
        probing.parse_message(m.ScreenExpression, '{"action": "EYE_SLEEPING"}')
    text = str(caught.value)
    assert "action" in text and "EYE_SLEEPING" in text and "EYE_SLEEP," in text
    with pytest.raises(UsageError, match="action"):
        probing.parse_message(m.ScreenExpression, '{"action": 99}')


def test_nested_enum_names_are_converted() -> None:
    frame = {"radar_id": 0, "target_state": "MOVING", "movement_distance": 1,
             "movement_energy": 2, "stationary_distance": 3, "stationary_energy": 4,
             "detection_distance": 5}
    raw = enum_values({"stamp_ns": 1, "device_id": 0, "sensors": [frame]},
                      m.LD2410TargetDataFrameArray)
    assert raw["sensors"][0]["target_state"] == m.TargetState.MOVING.value
    decoded = msgspec.convert(raw, m.LD2410TargetDataFrameArray)
    assert decoded.sensors[0].target_state is m.TargetState.MOVING


def test_summaries_show_names_and_raw_shows_numbers() -> None:
    msg = m.EyeLidControl(stamp_ns=3, eye_id=m.EyeId.BOTH, top_lid_position=10,
                          bottom_lid_position=20)
    named = json.loads(summarize(msg))
    assert named["eye_id"] == "BOTH" and named["top_lid_position"] == 10
    assert json.loads(summarize(msg, names=False))["eye_id"] == 2
    payload = keys.LIDS.codec.encode(msg)
    key = keys.absolute("buddy", keys.LIDS.pattern)
    assert '"eye_id":"BOTH"' in describe(key, payload)
    assert '"eye_id":2' in describe(key, payload, names=False)


def test_a_message_without_enums_is_printed_as_before() -> None:
    msg = m.PupilControl(stamp_ns=3, dilation_percentage=33)
    assert summarize(msg) == msgspec.json.encode(msg).decode()


def test_schemas_name_the_members_of_integer_enums() -> None:
    schema = json.loads(schemas.generate()["messages/ScreenExpression.json"])
    action = schema["$defs"]["ExpressionAction"]
    assert action["enum"][action["x-enum-names"].index("EYE_SLEEP")] == 1
    assert len(action["x-enum-names"]) == len(action["enum"]) == len(m.ExpressionAction)
    assert "1 = EYE_SLEEP" in action["description"]


# --- what the verbs decide ------------------------------------------------------------


@pytest.mark.parametrize(("key", "known"), [
    ("buddybot/buddy/eyes/pupil", True),
    ("buddybot/buddy/camera/*/image", True),
    ("buddybot/buddy/**", True),
    ("buddybot/*/eyes/expression", True),
    ("buddybot/buddy/eyes/nothing", False),
    ("buddybot/buddy/eye/pupil", False),
])
def test_catalogue_matches_names_unknown_keys(key: str, known: bool) -> None:
    assert bool(probing.catalogue_matches(key)) is known


# --- the bounded connection ---------------------------------------------------------


def test_a_probe_config_gives_up_and_a_service_config_waits() -> None:
    probe = session.zenoh_config(connect=["tcp/127.0.0.1:7447"], connect_timeout_s=1.5)
    service = session.zenoh_config(connect=["tcp/127.0.0.1:7447"])
    assert json.loads(probe.get_json("connect/timeout_ms")) == 1500
    assert json.loads(service.get_json("connect/timeout_ms")) == -1


def test_a_probe_without_router_fails_fast_naming_endpoint_and_reason() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    args = argparse.Namespace()
    ctx = ServiceContext(name="probe-test", args=args, config=default_config(), robot="buddy",
                         connect=[endpoint])
    started = time.monotonic()
    with pytest.raises(session.RouterUnreachable) as caught:
        ctx.probe(0.5)
    assert time.monotonic() - started < 5
    text = str(caught.value)
    assert endpoint in text and "refused" in text.lower() and "0.5 s" in text
    assert isinstance(caught.value, ConnectionError)  # callers catching the old error


# --- Zenoh's log lines --------------------------------------------------------------

REFUSED = (
    "\x1b[2m2026-11-23T09:25:15.579753Z\x1b[0m \x1b[34mDEBUG\x1b[0m ThreadId(01) "
    "\x1b[2mzenoh::net::runtime::orchestrator\x1b[0m\x1b[2m:\x1b[0m Unable to connect to "
    "configured peer tcp/127.0.0.1:1! Can not create a new TCP link bound to "
    "tcp/127.0.0.1:1: [127.0.0.1:1: Connection refused (os error 111) at "
    "/root/.cargo/x/io/zenoh-link-commons/src/tcp.rs:105.] at /root/.cargo/x/unicast.rs:9. "
    "Retry in 500ms.\n"
)
WARNING = ("2026-11-23T09:25:16.579810Z  WARN ThreadId(01) zenoh::net::routing: "
           "something odd at /root/.cargo/x/orchestrator.rs:388.\n")


def test_zenoh_lines_become_log_records_and_reasons(caplog: pytest.LogCaptureFixture) -> None:
    read_end, write_end = os.pipe()
    out_read, out_write = os.pipe()
    session.forget_connect_failures()
    pump = threading.Thread(target=session._pump_zenoh_log, args=(read_end, out_write))
    with caplog.at_level(logging.DEBUG, logger="zenoh"):
        pump.start()
        os.write(write_end, REFUSED.encode() + WARNING.encode() + b"a child's own line\n")
        os.close(write_end)
        pump.join(10)
    os.close(out_write)
    with os.fdopen(out_read, "rb") as passed:
        assert passed.read() == b"a child's own line\n"
    assert session.connect_failures() == {
        "tcp/127.0.0.1:1": "Connection refused (os error 111)"}
    records = [(r.levelno, r.getMessage()) for r in caplog.records if r.name == "zenoh"]
    assert (logging.WARNING, "zenoh::net::routing: something odd") in records
    refused = [text for level, text in records if "Unable to connect" in text]
    assert refused and "Retry" not in refused[0] and ".rs:" not in refused[0]
    assert all(level == logging.DEBUG for level, text in records if "Unable" in text)
    session.forget_connect_failures()


def test_zenoh_log_is_not_rerouted_when_stdout_is_captured(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert session.route_zenoh_log("INFO") is False
    print("still captured")
    assert capsys.readouterr().out == "still captured\n"


def test_zenoh_error_texts_lose_their_source_locations() -> None:
    text = ("Unable to connect to any of [Single(tcp/127.0.0.1:1)]. Timeout! at "
            "/root/.cargo/git/checkouts/zenoh/cc83980/zenoh/src/net/runtime/orchestrator.rs:388.")
    assert session._clean(text) == "Unable to connect to any of [Single(tcp/127.0.0.1:1)]. Timeout!"


# --- as processes: no router, wrong router --------------------------------------------

# A probe that did not give up would run into `bb`'s own timeout (an error); the
# bound itself is what the probe says it waited, never a wall time measured here.


PROBES = [
    ("nodes",),
    ("echo", "eyes/pupil"),
    ("hz", "eyes/pupil"),
    ("pub", "eyes/pupil", '{"dilation_percentage": 5}'),
    ("call", "audio/stop"),
]


@pytest.mark.integration
@pytest.mark.parametrize("verb", PROBES, ids=[p[0] for p in PROBES])
def test_every_probe_gives_up_on_a_refused_port_saying_why(verb: tuple[str, ...]) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    line = one_line_error(bb(*verb, "--connect", endpoint, "--timeout", "1"))
    assert endpoint in line and "Connection refused" in line, line
    assert "gave up after 1 s" in line


@pytest.mark.integration
def test_the_default_timeout_bounds_the_connection_too() -> None:
    """`echo` without --timeout runs until stopped, but not without a router."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    line = one_line_error(bb("echo", "eyes/pupil", "--connect", endpoint))
    assert endpoint in line and "gave up after 5 s" in line


@pytest.mark.integration
def test_tls_to_a_tcp_router_is_named_as_a_protocol_problem(router: InProcessRouter) -> None:
    endpoint = f"tls/127.0.0.1:{router.port}"
    line = one_line_error(bb("nodes", "--connect", endpoint, "--timeout", "1"))
    assert endpoint in line and "no Zenoh session follows" in line and "wrong protocol" in line


@pytest.mark.integration
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


@pytest.mark.integration
def test_echo_and_hz_name_an_unknown_key(endpoint: str) -> None:
    for verb in ("echo", "hz"):
        line = one_line_error(bb(verb, "eyes/nothing", "--connect", endpoint, "--timeout", "1"))
        assert "buddybot/buddy/eyes/nothing" in line and "matches no key of the catalogue" in line


@pytest.mark.integration
def test_echo_and_hz_name_a_robot_without_nodes(endpoint: str,
                                                node_factory: Callable[..., Node]) -> None:
    node_factory("somebody")  # robot buddy is alive; robot r2 is not
    for verb in ("echo", "hz"):
        line = one_line_error(bb(verb, "eyes/pupil", "--robot", "r2", "--connect", endpoint,
                                 "--timeout", "1"))
        assert "no node of robot 'r2' is alive" in line, line
    nodes = bb("nodes", "--robot", "r2", "--connect", endpoint)
    assert "no live node of robot 'r2'" in one_line_error(nodes) and nodes.stdout == ""


# --- Zenoh's log and access control, as processes -------------------------------------


@pytest.mark.integration
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


@pytest.mark.integration
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
