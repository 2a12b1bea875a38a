"""One exit policy for every verb and service: 2 usage/config, 1 run-time failure, 0 stop.

Each case runs `run_main` in a child process (it installs signal handlers,
which must not touch pytest's own), with a `main` that ends the given way.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from buddybot.runtime import errors

pytestmark = pytest.mark.integration  # each case runs in a child process

CHILD = """
import argparse, sys
from buddybot.runtime import errors
from buddybot.runtime.service import run_main

how = sys.argv[1]

def main(ctx):
    if how == "usage":
        raise errors.UsageError("no such key 'radar/nope'")
    if how == "config":
        raise errors.ConfigError("robot.toml: key 'camera.fps': expected > 0")
    if how == "duplicate":
        raise errors.DuplicateNodeError("another camera is already running")
    if how == "service":
        raise errors.ServiceError("audio/play_sound: no reply within 1 s")
    if how == "interrupt":
        raise KeyboardInterrupt
    if how == "bug":
        raise RuntimeError("a bug keeps its traceback")
    return int(how)

args = argparse.Namespace(config=None, robot=None, connect=None, log_level="ERROR")
sys.exit(run_main("probe", args, main))
"""


def run(how: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", CHILD, how], capture_output=True, text=True,
                          timeout=60)


@pytest.mark.parametrize(("how", "status", "line"), [
    ("usage", 2, "buddybot probe: no such key 'radar/nope'"),
    ("config", 2, "buddybot: config error: robot.toml: key 'camera.fps': expected > 0"),
    ("duplicate", 2, "buddybot: config error: another camera is already running"),
    ("service", 1, "buddybot probe: audio/play_sound: no reply within 1 s"),
    ("interrupt", 0, ""),
    ("0", 0, ""),
    ("1", 1, ""),
])
def test_each_ending_has_its_status_and_one_line(how: str, status: int, line: str) -> None:
    result = run(how)
    assert result.returncode == status, result.stderr
    if line:
        assert result.stderr.strip().splitlines() == [line], result.stderr
    assert "Traceback" not in result.stderr


def test_a_bug_is_not_hidden() -> None:
    result = run("bug")
    assert result.returncode == 1
    assert "Traceback" in result.stderr and "RuntimeError: a bug" in result.stderr


def test_exit_status_table() -> None:
    assert errors.exit_status(errors.UsageError("x")) == errors.EXIT_USAGE == 2
    assert errors.exit_status(errors.ConfigError("x")) == 2
    assert errors.exit_status(errors.ServiceError("x")) == errors.EXIT_FAILURE == 1
    assert errors.exit_status(ConnectionError("x")) == 1
    assert errors.exit_status(KeyboardInterrupt()) == errors.EXIT_OK == 0


def test_cli_usage_errors_exit_2_without_a_router() -> None:
    """A wrong key is refused before any connection is tried."""
    result = subprocess.run(
        [sys.executable, "-m", "buddybot", "call", "radar/presence", "--timeout", "1"],
        capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert "not a service of the catalogue" in result.stderr


def test_keys_ignores_a_broken_config_that_stops_config(tmp_path: Path) -> None:
    """Verbs that never read the config cannot be stopped by a bad one."""
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nfps = 'fast'\n")
    env = {**os.environ, "BUDDYBOT_CONFIG": str(bad)}
    keys_run = subprocess.run([sys.executable, "-m", "buddybot", "keys"], capture_output=True,
                              text=True, timeout=60, env=env)
    assert keys_run.returncode == 0 and "radar/presence" in keys_run.stdout
    config_run = subprocess.run([sys.executable, "-m", "buddybot", "config"],
                                capture_output=True, text=True, timeout=60, env=env)
    assert config_run.returncode == 2 and "camera.fps" in config_run.stderr
