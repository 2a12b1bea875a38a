"""`buddybot.sdk.bot`: the standard flags and config resolution, a bounded connect that
fails with NoRouter naming the endpoint (no router: nothing is started)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pytest

from buddybot.sdk import Bot, NoRouter, add_arguments
from buddybot.tools.testing import free_port


def test_no_router_is_reported_within_the_timeout_naming_the_endpoint() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nothing listens there
    started = time.monotonic()
    with pytest.raises(NoRouter) as caught:
        Bot.connect(connect=[endpoint], timeout=0.5)
    assert time.monotonic() - started < 5
    assert endpoint in str(caught.value) and caught.value.endpoints == [endpoint]


def test_the_standard_flags_and_the_config_file_choose_the_router(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config = tmp_path / "bot.toml"
    config.write_text(f'[zenoh]\nconnect = ["{endpoint}"]\n')
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--config", str(config), "--log-level", "WARNING"])
    with pytest.raises(NoRouter) as caught:
        Bot.from_args(args, timeout=0.3)
    assert caught.value.endpoints == [endpoint]
