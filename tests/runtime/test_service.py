"""Common options merged over the config: a given flag is never replaced by it."""

from __future__ import annotations

import argparse
import subprocess

import pytest

from buddybot.runtime.errors import ConfigError
from buddybot.runtime.sdnotify import Notifier
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


class CountingNotifier(Notifier):
    def __init__(self) -> None:
        super().__init__(None)
        self.pings = 0

    def watchdog(self) -> bool:
        self.pings += 1
        return True


def test_the_watchdog_is_fed_only_while_every_alive_check_holds() -> None:
    """A web listener that died must stop the pings, so systemd restarts the service."""
    notifier = CountingNotifier()
    ctx = resolve(argparse.Namespace(config=None, robot=None, connect=None), "test")
    ctx.notifier = notifier
    listening = [True]
    ctx.alive_checks.append(lambda: listening[0])
    ctx.feed_watchdog()
    listening[0] = False
    ctx.feed_watchdog()
    ctx.feed_watchdog()
    assert notifier.pings == 1 and not ctx.alive()


@pytest.mark.integration
def test_a_robot_id_of_thousands_of_characters_is_refused_in_one_short_line() -> None:
    """It was accepted, and became every key's prefix."""
    result = subprocess.run(buddybot_argv("nodes", "--robot", "r" * 5000, "--timeout", "1"),
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    [line] = result.stderr.strip().splitlines()
    assert line.endswith("is not a valid id (1-64 letters, digits, '-', '_')") and len(line) < 200
