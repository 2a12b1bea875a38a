"""The `buddybot` decoder plugin of zenoh-cli, on a real router."""

from __future__ import annotations

import shutil
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, retry_until

pytestmark = pytest.mark.integration


@pytest.mark.skipif(shutil.which("zenoh") is None and not Path(sys.executable).with_name(
    "zenoh").exists(), reason="zenoh-cli not installed")
def test_zenoh_cli_decoder_plugin(endpoint: str, node_factory: Callable[..., Node],
                                  log_dir: Path) -> None:
    exe = str(Path(sys.executable).with_name("zenoh"))
    proc = Process([exe, "--mode", "client", "--connect", endpoint,
                    "--cfg", "scouting/multicast/enabled:false",
                    "subscribe", "-k", "buddybot/**", "--decoder", "buddybot"], "zenoh-cli",
                   log_dir)
    try:
        talker = node_factory("talker")
        pupil = talker.publisher(keys.PUPIL)
        image = talker.publisher(keys.CAMERA_IMAGE, camera="front")

        def both_seen() -> bool:
            pupil.put(m.PupilControl(stamp_ns=3, dilation_percentage=33))
            image.put(m.Image(stamp_ns=4, frame_id="f", width=1, height=1, encoding="jpeg",
                              data=b"\xff\xd8"))
            out = proc.output()
            return '"dilation_percentage":33.0' in out and "<2 bytes>" in out

        retry_until(both_seen, 30, 0.3, "zenoh-cli printing decoded messages")
    finally:
        proc.stop()
