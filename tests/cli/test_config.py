"""`buddybot config`: the effective configuration, from the file and the command line."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest

from tests.cli.process import bb

pytestmark = pytest.mark.integration


CONFIG_FILE = """
[robot]
id = "from-file"

[zenoh]
connect = ["tcp/10.1.2.3:7447"]

[controller]
greet_dwell_s = 2.75
greeting_sound = "hello-there"

[camera]
jpeg_quality = 61
"""


def config_text(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    """Run `buddybot config ARGS` in this process (through the CLI's entry point,
    so the test does not depend on how the verbs are laid out); its stdout."""
    from buddybot.cli import main

    capsys.readouterr()
    status = main(["config", *args])
    out, err = capsys.readouterr()
    assert status == 0, err
    return out


def config_output(capsys: pytest.CaptureFixture[str], *args: str) -> dict[str, Any]:
    return tomllib.loads(config_text(capsys, *args))


def test_config_prints_values_from_the_file_and_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("BUDDYBOT_CONFIG", raising=False)
    defaults = config_output(capsys)
    # The file's values differ from the defaults, so seeing them proves the file was read.
    assert defaults["controller"]["greet_dwell_s"] != 2.75
    assert defaults["camera"]["jpeg_quality"] != 61
    assert defaults["robot"]["id"] != "from-file"

    path = tmp_path / "robot.toml"
    path.write_text(CONFIG_FILE)
    from_file = config_output(capsys, "--config", str(path))
    assert from_file["robot"]["id"] == "from-file"
    assert from_file["zenoh"]["connect"] == ["tcp/10.1.2.3:7447"]
    assert from_file["controller"]["greet_dwell_s"] == 2.75
    assert from_file["controller"]["greeting_sound"] == "hello-there"
    assert from_file["camera"]["jpeg_quality"] == 61
    # Everything the file does not set keeps its default.
    assert from_file["controller"]["regreet_cooldown_s"] == defaults["controller"][
        "regreet_cooldown_s"]
    assert from_file["audio"] == defaults["audio"]

    # The command line wins over the file, and only for what it sets.
    both = config_output(capsys, "--config", str(path), "--robot", "from-cli",
                         "--connect", "tcp/127.0.0.1:7999", "--connect", "tcp/127.0.0.1:7998")
    assert both["robot"]["id"] == "from-cli"
    assert both["zenoh"]["connect"] == ["tcp/127.0.0.1:7999", "tcp/127.0.0.1:7998"]
    assert both["controller"] == from_file["controller"]

    # $BUDDYBOT_CONFIG is read when there is no --config.
    monkeypatch.setenv("BUDDYBOT_CONFIG", str(path))
    assert config_output(capsys) == from_file


def test_config_output_round_trips_through_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """What `buddybot config` prints is a complete config that `--config` reads back
    to the same effective configuration (command-line values included)."""
    monkeypatch.delenv("BUDDYBOT_CONFIG", raising=False)
    path = tmp_path / "robot.toml"
    path.write_text(CONFIG_FILE)
    first = config_text(capsys, "--config", str(path), "--robot", "from-cli")
    effective = tmp_path / "effective.toml"
    effective.write_text(first)
    again = config_text(capsys, "--config", str(effective))
    assert again == first
    data = tomllib.loads(again)
    assert data["robot"]["id"] == "from-cli" and data["camera"]["jpeg_quality"] == 61


def test_config_refuses_a_bad_file_naming_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from buddybot.cli import main

    path = tmp_path / "robot.toml"
    path.write_text("[controller]\ngreet_dwell_s = -1.0\n")
    assert main(["config", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "greet_dwell_s" in err and "robot.toml" in err


def test_cli_config_prints_effective_config(tmp_path: Path) -> None:
    path = tmp_path / "ok.toml"
    path.write_text("[radar_presence]\nrange_m = 3.5\n")
    result = subprocess.run(
        [sys.executable, "-m", "buddybot", "config", "--config", str(path), "--robot", "zz"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert "range_m = 3.5" in result.stdout
    assert 'id = "zz"' in result.stdout


def test_json_is_one_document(endpoint: str) -> None:
    config = json.loads(bb("config", "--json", "--connect", endpoint, "--robot", "r9").stdout)
    assert config["robot"]["id"] == "r9" and config["zenoh"]["connect"] == [endpoint]
