"""`buddybot echo` as a process: decoded messages, images summarized, saying why nothing comes."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Collector,
    Process,
    buddybot_argv,
    retry_until,
)
from tests.cli.process import bb, one_line_error

pytestmark = pytest.mark.integration


def test_echo_prints_latched_value_and_exits_after_count(
    endpoint: str, node_factory: Callable[..., Node]
) -> None:
    pub = node_factory("talker").publisher(keys.PRESENCE)
    pub.put(m.PresenceDetection(stamp_ns=7, target_state=m.PresenceTarget.STANDING,
                                presence_state=m.PresenceState.IN_RANGE, distance_m=1.5))
    result = bb("echo", "radar/presence", "--connect", endpoint, "--count", "1",
                "--timeout", "20")
    assert result.returncode == 0, result.stderr
    # Enum fields by name; `--raw` keeps the wire's numbers.
    assert '"presence_state":"IN_RANGE"' in result.stdout and '"stamp_ns":7' in result.stdout


def test_echo_summarizes_images(endpoint: str, node_factory: Callable[..., Node],
                                log_dir: Path) -> None:
    proc = Process(buddybot_argv("echo", "buddybot/buddy/camera/*/image", "--connect", endpoint,
                                 "--count", "1", "--timeout", "30", "--show-key"), "echo", log_dir)
    pub = node_factory("cam").publisher(keys.CAMERA_IMAGE, camera="front")
    image = m.Image(stamp_ns=1, frame_id="front", width=640, height=480, encoding="bgr8",
                    data=bytes(640 * 480 * 3))
    try:
        retry_until(lambda: pub.put(image) or not proc.alive(), 30, 0.2, "echo to finish")
        out = proc.output()
        assert "camera/front/image" in out and "<921600 bytes>" in out and '"width": 640' in out
        assert proc.proc.wait(10) == 0
    finally:
        proc.stop()


def test_echo_times_out_with_status_1(endpoint: str) -> None:
    result = bb("echo", "eyes/pupil", "--connect", endpoint, "--count", "1", "--timeout", "1")
    assert result.returncode == 1 and "got 0 of 1" in result.stderr


def test_echo_without_timeout_says_once_why_nothing_comes(endpoint: str, log_dir: Path) -> None:
    """Running until stopped is what `echo` is for, but not silently."""
    echo = Process(buddybot_argv("echo", "eyes/nothing", "--connect", endpoint), "echo", log_dir)
    try:
        echo.wait_for_output("nothing yet", timeout=30)
        assert "matches no key of the catalogue" in echo.output() and echo.alive()
    finally:
        assert echo.stop() == 0


def test_echo_on_a_quiet_known_key_lists_who_is_alive(
        endpoint: str, node_factory: Callable[..., Node]) -> None:
    node_factory("somebody")
    line = retry_until(lambda: (r := bb("echo", "eyes/pupil", "--connect", endpoint,
                                        "--timeout", "1")) and "somebody" in r.stderr
                       and one_line_error(r), 30, 0.5, "echo naming the live node")
    assert "no publisher matches buddybot/buddy/eyes/pupil" in line


def test_enum_names_round_trip_through_pub_and_echo(
        endpoint: str, node_factory: Callable[..., Node], log_dir: Path) -> None:
    got = Collector[m.ScreenExpression](node_factory("listener"), keys.EXPRESSION)
    result = bb("pub", "eyes/expression", '{"action": "EYE_SLEEP"}', "--connect", endpoint)
    assert result.returncode == 0, result.stderr
    assert got.wait_for(timeout=10).action is m.ExpressionAction.EYE_SLEEP
    talker = Process(buddybot_argv("pub", "eyes/expression", '{"action": "EYE_SLEEP"}',
                                   "--rate", "20", "--connect", endpoint), "talker", log_dir)
    try:
        named = bb("echo", "eyes/expression", "-n", "1", "--timeout", "20", "--connect", endpoint)
        raw = bb("echo", "eyes/expression", "-n", "1", "--timeout", "20", "--raw",
                 "--connect", endpoint)
    finally:
        talker.stop()
    assert named.returncode == 0 and raw.returncode == 0, (named.stderr, raw.stderr)
    assert json.loads(named.stdout)["action"] == "EYE_SLEEP"
    assert json.loads(raw.stdout)["action"] == 1
