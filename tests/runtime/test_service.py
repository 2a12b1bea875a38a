"""Common options merged over the config: a given flag is never replaced by it."""

from __future__ import annotations

import argparse

import pytest

from buddybot.runtime.errors import ConfigError
from buddybot.runtime.service import resolve


def test_empty_robot_flag_is_refused_not_replaced_by_the_config_id() -> None:
    # `args.robot or config.robot.id` used to turn `--robot ""` into "buddy" silently.
    args = argparse.Namespace(config=None, robot="", connect=None)
    with pytest.raises(ConfigError, match="--robot"):
        resolve(args, "test")


def test_absent_flags_take_the_config() -> None:
    ctx = resolve(argparse.Namespace(config=None, robot=None, connect=None), "test")
    assert ctx.robot == "buddy"
    assert ctx.connect == list(ctx.config.zenoh.connect)
