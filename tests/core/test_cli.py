"""Every `buddybot` verb, run as a real process against a real router."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import SERVICES
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until

pytestmark = pytest.mark.integration  # every verb runs as a real process (most against a router)

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
        assert "--connect" in result.stdout


def test_run_help_lists_every_service() -> None:
    out = bb("run", "--help").stdout
    for entry in SERVICES:
        assert entry.name in out


def test_unknown_service_is_refused() -> None:
    result = bb("run", "teleporter")
    assert result.returncode == 2 and "invalid choice" in result.stderr


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


def test_echo_prints_latched_value_and_exits_after_count(
    endpoint: str, node_factory: Callable[..., Node]
) -> None:
    pub = node_factory("talker").publisher(keys.PRESENCE)
    pub.put(m.PresenceDetection(stamp_ns=7, target_state=m.PresenceTarget.STANDING,
                                presence_state=m.PresenceState.IN_RANGE, distance_m=1.5))
    result = bb("echo", "radar/presence", "--connect", endpoint, "--count", "1",
                "--timeout", "20")
    assert result.returncode == 0, result.stderr
    # Enum fields by name (issue 13); `--raw` keeps the wire's numbers.
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
