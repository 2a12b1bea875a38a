"""`buddybot param`: its pure parts, and as processes against real services."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from buddybot.cli import param as param_cli
from buddybot.contract import messages as m
from buddybot.radar.settings import RadarPresenceSettings
from buddybot.runtime import registry
from buddybot.runtime.config import parse_config
from buddybot.runtime.errors import UsageError
from buddybot.runtime.params import describe, validate
from buddybot.tools.testing import Process
from tests.cli.process import bb_on, wait_params
from tests.runtime.test_params import Tuning


def test_parse_value_is_json_else_text() -> None:
    assert param_cli.parse_value("1.5") == 1.5
    assert param_cli.parse_value("true") is True
    assert param_cli.parse_value('["a"]') == ["a"]
    assert param_cli.parse_value("front") == "front"


def test_dump_is_toml_the_config_accepts_and_load_reads_it_back(tmp_path: Path) -> None:
    settings = RadarPresenceSettings(range_m=1.25)
    reply = m.ParamReply(node="radar-presence", table="radar_presence",
                         params=describe(settings))
    path = tmp_path / "dump.toml"
    path.write_bytes(param_cli.dump_toml(reply))
    config = parse_config(path.read_bytes(), str(path))
    assert config.section(RadarPresenceSettings) == settings
    values: dict[str, Any] = param_cli.load_table(str(path), "radar_presence")
    assert validate(RadarPresenceSettings(), values)[0] == settings


def test_load_table_errors_are_usage_errors(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="cannot read"):
        param_cli.load_table(str(tmp_path / "missing.toml"), "t")
    bad = tmp_path / "bad.toml"
    bad.write_text("[t\n")
    with pytest.raises(UsageError, match="not valid TOML"):
        param_cli.load_table(str(bad), "t")
    deep = tmp_path / "deep.toml"
    deep.write_text("[t]\na = " + "[" * 33 + "]" * 33 + "\n")
    with pytest.raises(UsageError, match="nested deeper than 32 levels"):
        param_cli.load_table(str(deep), "t")
    other = tmp_path / "other.toml"
    other.write_text("[u]\na = 1\n")
    with pytest.raises(UsageError, match=r"no \[t\] table"):
        param_cli.load_table(str(other), "t")


def test_table_lines_mark_live_and_restart() -> None:
    lines = param_cli.table_lines(describe(Tuning()))
    assert lines[0].startswith("gain") and lines[0].endswith("live")
    assert next(x for x in lines if x.startswith("port")).endswith("restart")


@pytest.mark.parametrize("entry", registry.SERVICES, ids=lambda e: e.name)
def test_every_table_dumps_to_toml_the_config_reads_back(entry: registry.Entry) -> None:
    kind = entry.settings_type()
    assert entry.table is not None
    reply = m.ParamReply(node=entry.name, table=entry.table, params=describe(kind()))
    config = parse_config(param_cli.dump_toml(reply), "<dump>")
    assert config.section(kind) == kind()


Spawn = Callable[..., Process]


@pytest.mark.integration
def test_list_get_set_and_refusals(spawn: Spawn, endpoint: str) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    listed = bb_on(endpoint, "param", "list", "radar-presence")
    assert listed.returncode == 0, listed.stderr
    lines = {line.split()[0]: line for line in listed.stdout.splitlines()[1:]}
    assert lines["range_m"].split()[1] == "2.0" and lines["range_m"].endswith("live")
    assert lines["max_sensors"].endswith("restart")
    as_json = json.loads(bb_on(endpoint, "param", "list", "radar-presence", "--json").stdout)
    assert {p["name"]: p["live"] for p in as_json}["exit_margin_m"] is True

    assert bb_on(endpoint, "param", "set", "radar-presence", "range_m", "1.25").returncode == 0
    got = bb_on(endpoint, "param", "get", "radar-presence", "range_m")
    assert got.returncode == 0 and got.stdout.strip() == "1.25"

    refused = bb_on(endpoint, "param", "set", "radar-presence", "range_m", "20")
    assert refused.returncode == 1
    assert "range_m = 20 refused: allowed > 0 and <= 10" in refused.stderr
    assert "Traceback" not in refused.stderr
    restart = bb_on(endpoint, "param", "set", "radar-presence", "max_sensors", "4")
    assert restart.returncode == 1 and "max_sensors needs a restart" in restart.stderr
    assert bb_on(endpoint, "param", "get", "radar-presence", "range_m").stdout.strip() == "1.25"

    unknown = bb_on(endpoint, "param", "set", "radar-presence", "rang_m", "1")
    assert unknown.returncode == 2 and "no parameter 'rang_m'" in unknown.stderr
    usage = bb_on(endpoint, "param", "set", "radar-presence", "range_m")
    assert usage.returncode == 2 and "usage: buddybot param set NODE FIELD VALUE" in usage.stderr


@pytest.mark.integration
def test_dump_then_load_round_trip(spawn: Spawn, endpoint: str, tmp_path: Path) -> None:
    spawn("radar-presence", "--absence-hold-s", "0.7")
    wait_params(endpoint, "radar-presence")
    assert bb_on(endpoint, "param", "set", "radar-presence", "range_m", "1.25").returncode == 0
    dump = tmp_path / "presence.toml"
    result = bb_on(endpoint, "param", "dump", "radar-presence", "-o", str(dump))
    assert result.returncode == 0, result.stderr
    # What `--config` accepts, with the values the node runs with.
    config = parse_config(dump.read_bytes(), str(dump))
    assert config.section(RadarPresenceSettings) == RadarPresenceSettings(
        range_m=1.25, absence_hold_s=0.7)

    assert bb_on(endpoint, "param", "set", "radar-presence", "range_m", "3").returncode == 0
    loaded = bb_on(endpoint, "param", "load", "radar-presence", str(dump))
    assert loaded.returncode == 0, loaded.stderr
    assert "range_m changed" in loaded.stdout
    assert bb_on(endpoint, "param", "get", "radar-presence", "range_m").stdout.strip() == "1.25"
    again = bb_on(endpoint, "param", "dump", "radar-presence")
    assert again.stdout.splitlines()[1:] == dump.read_text().splitlines()[1:]

    deep = tmp_path / "deep.toml"  # a RecursionError traceback (exit 1) before
    deep.write_text("[radar_presence]\nrange_m = " + "[" * 5000 + "]" * 5000 + "\n")
    refused = bb_on(endpoint, "param", "load", "radar-presence", str(deep))
    assert refused.returncode == 2, refused.stderr
    assert refused.stderr.strip().splitlines() == [
        f"buddybot param: {deep}: not valid TOML: nested deeper than 32 levels (line 2)"]


@pytest.mark.integration
def test_controller_greeting_dwell_is_live(spawn: Spawn, endpoint: str) -> None:
    spawn("controller")
    wait_params(endpoint, "controller")
    result = bb_on(endpoint, "param", "set", "controller", "greet_dwell_s", "2.5")
    assert result.returncode == 0, result.stderr
    assert bb_on(endpoint, "param", "get", "controller", "greet_dwell_s").stdout.strip() == "2.5"
    camera = bb_on(endpoint, "param", "set", "controller", "camera", "side")
    assert camera.returncode == 1 and "camera needs a restart" in camera.stderr


@pytest.mark.integration
def test_camera_settings_are_readable_and_need_a_restart(spawn: Spawn, endpoint: str) -> None:
    """A service without live fields still exposes its settings: listed, each marked
    restart, and a set refused without touching the running value."""
    spawn("camera", "--sim", "--fps", "5")
    wait_params(endpoint, "camera")
    listed = json.loads(bb_on(endpoint, "param", "list", "camera", "--json").stdout)
    by_name = {p["name"]: p for p in listed}
    assert by_name["fps"]["value"] == 5 and not any(p["live"] for p in listed)
    refused = bb_on(endpoint, "param", "set", "camera", "jpeg_quality", "50")
    assert refused.returncode == 1 and "needs a restart" in refused.stderr


@pytest.mark.integration
def test_no_answer_gives_up_after_the_timeout(router: object, endpoint: str) -> None:
    start = time.monotonic()
    result = bb_on(endpoint, "param", "list", "nobody-here", timeout="0.5")
    assert result.returncode == 1
    assert "nobody-here did not answer" in result.stderr
    assert time.monotonic() - start < 20
