"""Common options merged over the config: a given flag is never replaced by it."""

from __future__ import annotations

import argparse
import subprocess

import pytest

from buddybot.runtime.errors import ConfigError
from buddybot.runtime.service import resolve
from buddybot.tools.testing import buddybot_argv


def test_empty_robot_flag_is_refused_not_replaced_by_the_config_id() -> None:
    # `args.robot or config.robot.id` used to turn `--robot ""` into "buddy" silently.
    args = argparse.Namespace(config=None, robot="", connect=None)
    with pytest.raises(ConfigError, match="--robot"):
        resolve(args, "test")


def test_absent_flags_take_the_config() -> None:
    ctx = resolve(argparse.Namespace(config=None, robot=None, connect=None), "test")
    assert ctx.robot == "buddy"
    assert ctx.connect == list(ctx.config.zenoh.connect)


@pytest.mark.integration
def test_a_robot_id_of_thousands_of_characters_is_refused_in_one_short_line() -> None:
    """It was accepted, and became every key's prefix."""
    result = subprocess.run(buddybot_argv("nodes", "--robot", "r" * 5000, "--timeout", "1"),
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    [line] = result.stderr.strip().splitlines()
    assert line.endswith("is not a valid id (1-64 letters, digits, '-', '_')") and len(line) < 200
