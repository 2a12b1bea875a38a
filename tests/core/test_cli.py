"""Every `buddybot` verb, run as a real process against a real router."""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.node import Node
from buddybot.core.registry import SERVICES
from buddybot.core.testing import Collector, Process, buddybot_argv, retry_until

VERBS = ["up", "router", "run", "echo", "hz", "pub", "call", "nodes", "keys", "config", "schemas",
         "radar"]


def bb(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv(*args), capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("verb", VERBS)
def test_every_verb_has_help(verb: str) -> None:
    result = bb(verb, "--help")
    assert result.returncode == 0, result.stderr
    assert "usage: buddybot" in result.stdout
    if verb not in ("run", "keys", "schemas"):
        assert "--connect" in result.stdout or verb in ("config",)


def test_run_help_lists_every_service() -> None:
    out = bb("run", "--help").stdout
    for entry in SERVICES:
        assert entry.name in out


def test_unknown_service_is_refused() -> None:
    result = bb("run", "teleporter")
    assert result.returncode == 2 and "invalid choice" in result.stderr


def test_echo_prints_latched_value_and_exits_after_count(
    endpoint: str, node_factory: Callable[..., Node]
) -> None:
    pub = node_factory("talker").publisher(keys.PRESENCE)
    pub.put(m.PresenceDetection(stamp_ns=7, target_state=m.PresenceTarget.STANDING,
                                presence_state=m.PresenceState.IN_RANGE, distance_m=1.5))
    result = bb("echo", "radar/presence", "--connect", endpoint, "--count", "1",
                "--timeout", "20")
    assert result.returncode == 0, result.stderr
    assert '"presence_state":1' in result.stdout and '"stamp_ns":7' in result.stdout


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


def test_pub_validates_and_publishes(endpoint: str, node_factory: Callable[..., Node]) -> None:
    got = Collector[m.EyeLidControl](node_factory("listener"), keys.LIDS)
    result = bb("pub", "eyes/lids", '{"eye_id": 2, "top_lid_position": 50, '
                '"bottom_lid_position": 50}', "--connect", endpoint)
    assert result.returncode == 0, result.stderr
    msg = got.wait_for(timeout=10)
    assert msg.eye_id == m.EyeId.BOTH and msg.top_lid_position == 50 and msg.stamp_ns > 0


@pytest.mark.parametrize(
    ("key", "payload", "needle"),
    [
        ("eyes/pupil", '{"dilation_percentage": 150}', "dilation_percentage"),
        ("eyes/pupil", '{"dilation": 15}', "dilation"),
        ("eyes/pupil", "not json", "not valid JSON"),
        ("eyes/nothing", "{}", "not a topic"),
        ("camera/*/image", "{}", "wildcard"),
    ],
)
def test_pub_refuses_bad_messages_naming_the_field(endpoint: str, key: str, payload: str,
                                                   needle: str) -> None:
    result = bb("pub", key, payload, "--connect", endpoint)
    assert result.returncode == 2
    assert needle in result.stderr


def test_pub_rate_and_hz(endpoint: str, log_dir: Path) -> None:
    talker = Process(buddybot_argv("pub", "eyes/pupil", '{"dilation_percentage": 5}',
                                   "--rate", "20", "--connect", endpoint), "talker", log_dir)
    try:
        result = bb("hz", "eyes/pupil", "--connect", endpoint, "--duration", "4")
        assert result.returncode == 0, result.stderr
        rates = [float(line.split()[2]) for line in result.stdout.splitlines()
                 if line.startswith("average rate")]
        assert rates and 10 < rates[-1] < 30
    finally:
        talker.stop()


def test_call_prints_reply_and_fails_without_server(
    endpoint: str, node_factory: Callable[..., Node]
) -> None:
    result = bb("call", "audio/stop", "--connect", endpoint, "--timeout", "1")
    assert result.returncode == 1 and "no reply" in result.stderr
    server = node_factory("server")
    server.serve(keys.AUDIO_STOP, lambda _req: m.TriggerReply(success=True, message="stopped"))
    result = retry_until(
        lambda: (r := bb("call", "audio/stop", "--connect", endpoint)).returncode == 0 and r,
        30, 0.5, "call to succeed")
    assert '"success":true' in result.stdout and "stopped" in result.stdout
    bad = bb("call", "audio/play_sound", '{"sound": ""}', "--connect", endpoint)
    assert bad.returncode == 2 and "sound" in bad.stderr


def test_nodes_lists_live_nodes(endpoint: str, node_factory: Callable[..., Node]) -> None:
    node_factory("visible-node")
    node_factory("other-robot-node", robot="r2")
    result = retry_until(
        lambda: (r := bb("nodes", "--connect", endpoint)) and "visible-node" in r.stdout and r,
        30, 0.5)
    assert "other-robot-node" not in result.stdout
    everyone = bb("nodes", "--connect", endpoint, "--all-robots").stdout
    assert "buddy/visible-node" in everyone and "r2/other-robot-node" in everyone


def test_keys_lists_catalogue() -> None:
    out = bb("keys").stdout
    for topic in keys.TOPICS:
        assert topic.pattern in out


def test_schemas_check(tmp_path: Path) -> None:
    assert bb("schemas", "--out", str(tmp_path)).returncode == 0
    assert bb("schemas", "--check", "--out", str(tmp_path)).returncode == 0
    (tmp_path / "keys.json").write_text("[]")
    result = bb("schemas", "--check", "--out", str(tmp_path))
    assert result.returncode == 1 and "keys.json" in result.stderr


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
