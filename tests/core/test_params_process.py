"""`buddybot param`, `topics` and `node info` as processes against real services."""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar.settings import RadarPresenceSettings
from buddybot.runtime.config import parse_config
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, buddybot_argv, retry_until

pytestmark = pytest.mark.integration

Spawn = Callable[..., Process]


def bb(endpoint: str, *args: str, timeout: str = "10") -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv(*args, "--connect", endpoint, "--timeout", timeout),
                          capture_output=True, text=True, timeout=60)


def wait_params(endpoint: str, node: str) -> None:
    """Until the node answers (it declares its queryable after connecting)."""
    retry_until(lambda: bb(endpoint, "param", "list", node, timeout="1").returncode == 0,
                30, 0.2, f"{node} answering params")


def test_list_get_set_and_refusals(spawn: Spawn, endpoint: str) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    listed = bb(endpoint, "param", "list", "radar-presence")
    assert listed.returncode == 0, listed.stderr
    lines = {line.split()[0]: line for line in listed.stdout.splitlines()[1:]}
    assert lines["range_m"].split()[1] == "2.0" and lines["range_m"].endswith("live")
    assert lines["max_sensors"].endswith("restart")
    as_json = json.loads(bb(endpoint, "param", "list", "radar-presence", "--json").stdout)
    assert {p["name"]: p["live"] for p in as_json}["exit_margin_m"] is True

    assert bb(endpoint, "param", "set", "radar-presence", "range_m", "1.25").returncode == 0
    got = bb(endpoint, "param", "get", "radar-presence", "range_m")
    assert got.returncode == 0 and got.stdout.strip() == "1.25"

    refused = bb(endpoint, "param", "set", "radar-presence", "range_m", "20")
    assert refused.returncode == 1
    assert "range_m = 20 refused: allowed > 0 and <= 10" in refused.stderr
    assert "Traceback" not in refused.stderr
    restart = bb(endpoint, "param", "set", "radar-presence", "max_sensors", "4")
    assert restart.returncode == 1 and "max_sensors needs a restart" in restart.stderr
    assert bb(endpoint, "param", "get", "radar-presence", "range_m").stdout.strip() == "1.25"

    unknown = bb(endpoint, "param", "set", "radar-presence", "rang_m", "1")
    assert unknown.returncode == 2 and "no parameter 'rang_m'" in unknown.stderr
    usage = bb(endpoint, "param", "set", "radar-presence", "range_m")
    assert usage.returncode == 2 and "usage: buddybot param set NODE FIELD VALUE" in usage.stderr


def test_dump_then_load_round_trip(spawn: Spawn, endpoint: str, tmp_path: Path) -> None:
    spawn("radar-presence", "--absence-hold-s", "0.7")
    wait_params(endpoint, "radar-presence")
    assert bb(endpoint, "param", "set", "radar-presence", "range_m", "1.25").returncode == 0
    dump = tmp_path / "presence.toml"
    result = bb(endpoint, "param", "dump", "radar-presence", "-o", str(dump))
    assert result.returncode == 0, result.stderr
    # What `--config` accepts, with the values the node runs with.
    config = parse_config(dump.read_bytes(), str(dump))
    assert config.section(RadarPresenceSettings) == RadarPresenceSettings(
        range_m=1.25, absence_hold_s=0.7)

    assert bb(endpoint, "param", "set", "radar-presence", "range_m", "3").returncode == 0
    loaded = bb(endpoint, "param", "load", "radar-presence", str(dump))
    assert loaded.returncode == 0, loaded.stderr
    assert "range_m changed" in loaded.stdout
    assert bb(endpoint, "param", "get", "radar-presence", "range_m").stdout.strip() == "1.25"
    again = bb(endpoint, "param", "dump", "radar-presence")
    assert again.stdout.splitlines()[1:] == dump.read_text().splitlines()[1:]


def test_controller_greeting_dwell_is_live(spawn: Spawn, endpoint: str) -> None:
    spawn("controller")
    wait_params(endpoint, "controller")
    result = bb(endpoint, "param", "set", "controller", "greet_dwell_s", "2.5")
    assert result.returncode == 0, result.stderr
    assert bb(endpoint, "param", "get", "controller", "greet_dwell_s").stdout.strip() == "2.5"
    camera = bb(endpoint, "param", "set", "controller", "camera", "side")
    assert camera.returncode == 1 and "camera needs a restart" in camera.stderr


def test_no_answer_gives_up_after_the_timeout(router: object, endpoint: str) -> None:
    start = time.monotonic()
    result = bb(endpoint, "param", "list", "nobody-here", timeout="0.5")
    assert result.returncode == 1
    assert "nobody-here did not answer" in result.stderr
    assert time.monotonic() - start < 20
    info = bb(endpoint, "node", "info", "nobody-here", timeout="0.5")
    assert info.returncode == 1 and "did not answer" in info.stderr


def test_node_info_lists_what_the_node_declared(spawn: Spawn, endpoint: str) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    result = bb(endpoint, "node", "info", "radar-presence")
    assert result.returncode == 0, result.stderr
    text = result.stdout
    publishers = text.split("publishers:")[1].split("subscriptions:")[0]
    assert "radar/presence" in publishers and "diagnostics/radar-presence" in publishers
    subscriptions = text.split("subscriptions:")[1].split("services:")[0]
    assert "radar/*/frames" in subscriptions
    assert "params/radar-presence" in text and "range_m = 2.0  (live)" in text
    report = json.loads(bb(endpoint, "node", "info", "radar-presence", "--json").stdout)
    assert "radar/presence" in report["info"]["publishers"]


def test_topics_shows_keys_rates_and_who(spawn: Spawn, endpoint: str, probe: Node) -> None:
    spawn("radar-bridge", "--sim", "--device-id", "5")
    spawn("radar-presence")
    frames = probe.key(keys.RADAR_FRAMES, device="5")
    got: list[str] = []
    probe.subscribe_raw(frames, lambda key, _p, _e: got.append(key))
    retry_until(lambda: len(got) > 5, 30, what="frames flowing")
    wait_params(endpoint, "radar-presence")
    result = bb(endpoint, "topics", "--json", timeout="3")
    assert result.returncode == 0, result.stderr
    rows = {r["key"]: r for r in json.loads(result.stdout)}
    row = rows["radar/5/frames"]
    assert 5.0 <= row["rate_hz"] <= 15.0  # the simulated LD2410 reports at 10 Hz
    assert row["publishers"] == ["radar-bridge"]
    # This test's own node ("probe", a full node) subscribes too; `topics` itself does not.
    assert row["subscribers"] == ["probe", "radar-presence"]
    assert row["type"] == "LD2410TargetDataFrameArray"
    assert "diagnostics/radar-presence" in rows
    text = bb(endpoint, "topics", timeout="2").stdout
    assert any(line.startswith("radar/5/frames") and "radar-bridge -> probe, radar-presence" in line
               for line in text.splitlines())


def test_a_reply_is_a_valid_message(spawn: Spawn, endpoint: str, probe: Node) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    reply = probe.call(keys.PARAMS, m.ParamRequest(op="get", name="range_m"),
                       node="radar-presence")
    assert isinstance(reply, m.ParamReply) and reply.params[0].value == 2.0


def test_camera_settings_are_readable_and_need_a_restart(spawn: Spawn, endpoint: str) -> None:
    """A service without live fields still exposes its settings: listed, each marked
    restart, and a set refused without touching the running value."""
    spawn("camera", "--sim", "--fps", "5")
    wait_params(endpoint, "camera")
    listed = json.loads(bb(endpoint, "param", "list", "camera", "--json").stdout)
    by_name = {p["name"]: p for p in listed}
    assert by_name["fps"]["value"] == 5 and not any(p["live"] for p in listed)
    refused = bb(endpoint, "param", "set", "camera", "jpeg_quality", "50")
    assert refused.returncode == 1 and "needs a restart" in refused.stderr
