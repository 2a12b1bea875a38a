"""The radar bridge (`buddybot run radar-bridge`): its command line merged over
`[radar_bridge]` (pure), and, marked `integration`, the process reading simulated
LD2410s on real ptys and serial-over-TCP through a real router: unplug and replug,
missing sensors, dropped links, garbage, noise detection, firmware differences."""

from __future__ import annotations

import argparse
import random
import time
from collections.abc import Callable

import pytest
import serial

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import bridge
from buddybot.radar import ld2410 as p
from buddybot.radar import ld2450 as p2
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.radar.sim import PtySensor
from buddybot.radar.sim_scene import Target
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, retry_until
from tests.radar.rig import StreamServer, diag_value, frames_of, standing, wait_more_frames

IN, OUT = m.PresenceState.IN_RANGE, m.PresenceState.OUT_OF_RANGE
Spawn = Callable[..., Process]


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    bridge.add_arguments(parser)
    return parser.parse_args(argv)


def test_flags_not_given_take_the_config() -> None:
    cfg = RadarBridgeSettings(sensors=["/dev/ttyUSB1"], device_id=3, baudrate=115200)
    opts = bridge.resolve_options(parse(), cfg)
    assert (opts.urls, opts.device_id, opts.baudrate, opts.sim) == (
        ["/dev/ttyUSB1"], 3, 115200, False)


def test_given_flags_win_over_the_config() -> None:
    cfg = RadarBridgeSettings(device_id=3, baudrate=115200)
    opts = bridge.resolve_options(parse("--sim", "--device-id", "0", "--baudrate", "9600"), cfg)
    # device_id 0 is a real id: it must not fall back to the config's 3.
    assert (opts.device_id, opts.baudrate, opts.sim) == (0, 9600, True)


@pytest.mark.parametrize(("argv", "flag"), [
    (("--sensor", "/dev/ttyUSB0", "--baudrate", "0"), "--baudrate"),
    (("--sensor", "/dev/ttyUSB0", "--device-id", "-1"), "--device-id"),
])
def test_zero_or_negative_is_refused_naming_the_flag_not_replaced(
        argv: tuple[str, ...], flag: str) -> None:
    # Not `args.x or cfg.x`, which silently turns 0 into the config value.
    with pytest.raises(ConfigError, match=flag):
        bridge.resolve_options(parse(*argv), RadarBridgeSettings())


def test_a_network_url_that_can_never_open_is_refused_at_start() -> None:
    """Not retried forever with pyserial's "'<=' not supported ..." as the reason."""
    cfg = RadarBridgeSettings(sensors=["/dev/ttyUSB0", "socket://radar-esp32.local"])
    with pytest.raises(ConfigError, match=r"radar_bridge.sensors\[1\]: .*no port"):
        bridge.resolve_options(parse(), cfg)
    with pytest.raises(ConfigError, match="--sensor: socket://:4001: no host"):
        bridge.resolve_options(parse("--sensor", "socket://:4001"), RadarBridgeSettings())
    opts = bridge.resolve_options(parse("--sensor", "socket://radar-esp32.local:4001"), cfg)
    assert opts.urls == ["socket://radar-esp32.local:4001"]


# --- the process -----------------------------------------------------------------------


@pytest.mark.integration
def test_unplug_and_replug_is_survived_and_the_other_sensor_goes_on(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    a = sensors("visit", "ttyA")
    b = sensors("nobody", "ttyB")
    frames = Collector(probe, keys.RADAR_FRAMES, device="4")
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    bridge = spawn("radar-bridge", "--sensor", a.path, "--sensor", b.path, "--device-id", "4")
    wait_more_frames(frames, 0, 5, 30)
    wait_more_frames(frames, 1, 5)

    diag.clear()
    a.unplug()
    down = diag.wait_for(lambda d: diag_value(d, "radar0.connected") is False, 20,
                         "radar 0 reported down")
    assert down.level == "WARN" and "radar 0" in down.message
    wait_more_frames(frames, 1, 10)  # the other sensor goes on meanwhile
    diag.clear()

    a.replug()
    up = diag.wait_for(lambda d: diag_value(d, "radar0.connected") is True, 30,
                       "radar 0 back")
    assert up.level == "OK"
    assert int(diag_value(up, "radar0.reconnects")) >= 1  # type: ignore[arg-type]
    assert int(diag_value(up, "reconnects")) >= 1  # type: ignore[arg-type]
    wait_more_frames(frames, 0, 10)
    assert bridge.alive()


@pytest.mark.integration
def test_bridge_sim_option_publishes_engineering_frames_at_10_hz(spawn: Spawn,
                                                                   probe: Node) -> None:
    frames = Collector(probe, keys.RADAR_FRAMES, device="3")
    spawn("radar-bridge", "--sim", "--device-id", "3")
    first = frames.wait_for(timeout=30, what="first frame")
    frames.wait_count(len(frames.messages) + 30, timeout=20)
    msgs = frames.messages[-30:]
    span_s = (msgs[-1].stamp_ns - msgs[0].stamp_ns) / 1e9
    assert 29 / span_s > 5.0, span_s  # ~10 Hz on a busy machine, never once a second
    frame = first.sensors[0]
    assert first.device_id == 3 and frame.radar_id == 0
    assert frame.moving_gate_energy is not None and len(frame.moving_gate_energy) == 9


@pytest.mark.integration
def test_bridge_reports_a_missing_sensor_and_reads_the_others(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    good = sensors("nobody")
    frames = Collector(probe, keys.RADAR_FRAMES)
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    # A short path the message shows whole (a long one is clipped): a folder that
    # never exists, so no test, parallel or not, can make it appear.
    missing = "/nonexistent/ttyUSB-not-here"
    bridge = spawn("radar-bridge", "--sensor", missing, "--sensor", good.path)
    wait_more_frames(frames, 1, 10, 30)
    d = diag.wait_for(lambda d: d.level == "WARN" and missing in d.message, 20, "missing named")
    assert "cannot open" in str(diag_value(d, "radar0.error"))
    assert frames_of(frames, 0) == 0
    assert bridge.alive()


def ld2410_recording(n: int) -> bytes:
    """Frame n of a recorded LD2410 stream: a person standing, frame n's number in
    its detection distance so the test can tell every frame apart."""
    return p.encode_report(p.Report(2, 0, 0, 150, 60, n))


def numbers(collector: Collector[m.LD2410TargetDataFrameArray]) -> list[int]:
    return [f.detection_distance for msg in collector.messages for f in msg.sensors]


def assert_no_gap(published: list[int], sent: list[int]) -> None:
    """Published frames are one run of the frames sent, in order, ending with the
    last frame sent whole: nothing received was lost."""
    assert published, "nothing published"
    first = published[0]
    assert published == sent[sent.index(first):], (published, sent)


@pytest.mark.integration
def test_a_stream_server_that_drops_and_reboots_is_read_again_losing_nothing_read(
        spawn: Spawn, probe: Node) -> None:
    """An ESP32 stream server on 127.0.0.1: the bridge reads `socket://` like a
    local port. The server drops the connection (reconnect at once), then
    reboots (connecting refused for a while, diagnostics say so): every frame
    the bridge received is published, in order, and reading goes on."""
    server = StreamServer(ld2410_recording)
    try:
        frames = Collector(probe, keys.RADAR_FRAMES)
        diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
        bridge = spawn("radar-bridge", "--sensor", server.url)
        wait_more_frames(frames, 0, 10, 30)

        server.drop()
        connected = len(numbers(frames))
        diag.wait_for(lambda d: int(diag_value(d, "radar0.reconnects") or 0) >= 1, 30,
                      "reconnected after the drop")
        first = server.sent[0]
        retry_until(lambda: first[-1] in numbers(frames), 10, what="the last frame before the drop")
        assert_no_gap(numbers(frames)[:numbers(frames).index(first[-1]) + 1], first)
        assert connected <= numbers(frames).index(first[-1]) + 1
        wait_more_frames(frames, 0, 5, 30)

        server.reboot()
        before = server.sent[-1]
        retry_until(lambda: before[-1] in numbers(frames), 10, what="the last frame before reboot")
        down = diag.wait_for(lambda d: "Connection refused" in str(diag_value(d, "radar0.error")),
                             30, "connecting refused while the ESP32 reboots")
        assert down.level == "ERROR" and diag_value(down, "radar0.connected") is False
        assert "radar 0" in down.message

        server.come_back()
        up = diag.wait_for(lambda d: diag_value(d, "radar0.connected") is True
                           and int(diag_value(d, "radar0.reconnects") or 0) >= 2, 30,
                           "reconnected after the reboot")
        assert up.level == "OK"
        wait_more_frames(frames, 0, 10, 30)
        published = numbers(frames)
        for sent in server.sent:  # each connection: one run, ending with its last frame
            mine = [n for n in published if sent[0] <= n <= sent[-1]]
            if sent is not server.sent[-1]:
                assert_no_gap(mine, sent)
        assert published == sorted(published) and len(set(published)) == len(published)
        assert server.connections == 3
        assert bridge.alive()
    finally:
        server.close()


def ld2450_recording(n: int) -> bytes:
    """Frame n of a recorded LD2450 stream: two people, frame n's number in the
    first one's x (sign-magnitude on the wire: odd frames left, even right)."""
    x = n % 4000 if n % 2 == 0 else -(n % 4000)
    return p2.encode_report(p2.Report((p2.Target(x, 1500, -20, 360), None,
                                       p2.Target(-800, 2400, 0, 320))))


def read_ld2450(port: serial.SerialBase, parser: p2.Parser, want: int) -> list[p2.Report]:
    """Read as the bridge reads (whatever is waiting, or one byte) until `want` reports."""
    reports: list[p2.Report] = []
    deadline = time.monotonic() + 20
    while len(reports) < want:
        assert time.monotonic() < deadline, f"{len(reports)} of {want} LD2450 reports"
        reports += [f for f in parser.feed(port.read(port.in_waiting or 1))
                    if isinstance(f, p2.Report)]
    return reports


def test_ld2450_bytes_cross_a_stream_server_whole_and_a_reboot_is_seen() -> None:
    """Real LD2450 frames from an ESP32-like stream server, read through pyserial's
    socket:// as the bridge reads a port: every report whole and in order; a
    drop and a reboot are errors the bridge turns into a reconnect."""
    server = StreamServer(ld2450_recording, period_s=0.02)
    try:
        parser = p2.Parser()
        port = serial.serial_for_url(server.url, baudrate=256000, timeout=0.2)
        reports = read_ld2450(port, parser, 20)
        xs = [r.slots[0].x_mm for r in reports if r.slots[0] is not None]
        frames = [abs(x) for x in xs]
        assert frames == list(range(frames[0], frames[0] + len(frames)))
        assert all((x > 0) == (n % 2 == 0) for x, n in zip(xs, frames, strict=True))
        assert all(r.slots[1] is None and r.slots[2] == p2.Target(-800, 2400, 0, 320)
                   for r in reports)
        assert parser.stats.bad_frames == 0

        server.reboot()
        with pytest.raises(serial.SerialException, match="disconnected"):
            while True:  # what is still buffered, then the close
                parser.feed(port.read(port.in_waiting or 1))
        port.close()
        with pytest.raises(serial.SerialException, match="Connection refused"):
            serial.serial_for_url(server.url, baudrate=256000, timeout=0.2)
        server.come_back()
        port = serial.serial_for_url(server.url, baudrate=256000, timeout=0.2)
        parser.reset()
        assert len(read_ld2450(port, p2.Parser(), 5)) >= 5
        port.close()
    finally:
        server.close()


@pytest.mark.integration
def test_report_frame_bytes_on_the_wire_match_what_the_bridge_publishes(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """16-bit distances with a 0x0A byte (266 cm) survive the whole serial path."""
    sensor = sensors(lambda t, rng: Target(3, 266, 40, 300, 100, 256), engineering=False)
    frames = Collector(probe, keys.RADAR_FRAMES)
    spawn("radar-bridge", "--sensor", sensor.path)
    msg = frames.wait_for(timeout=30, what="frame")
    f = msg.sensors[0]
    assert (f.target_state, f.movement_distance, f.movement_energy) == (3, 266, 40)
    assert (f.stationary_distance, f.stationary_energy, f.detection_distance) == (300, 100, 256)
    assert b"\x0a" in p.encode_report(p.Report(3, 266, 40, 300, 100, 256))


@pytest.mark.integration
def test_a_line_of_pure_garbage_is_reported_with_a_hint(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """What a sensor at another baud rate looks like: bytes, never a valid frame."""

    def garbage(t: float, rng: random.Random) -> Target:
        return Target(garbage=bytes(rng.randrange(256) for _ in range(20)), corrupt=True)

    sensor = sensors(garbage)
    frames = Collector(probe, keys.RADAR_FRAMES)
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    bridge = spawn("radar-bridge", "--sensor", sensor.path)
    d = diag.wait_for(lambda d: "wrong baud rate" in str(diag_value(d, "radar0.error")), 30,
                      "garbage reported")
    assert int(diag_value(d, "bad_frames")) > 0  # type: ignore[arg-type]
    assert frames.messages == []
    assert bridge.alive()


class Phase:
    """A scenario whose scene the test sets: `phase.target = Target(...)`."""

    def __init__(self, target: Target) -> None:
        self.target = target

    def __call__(self, t: float, rng: random.Random) -> Target:
        return self.target


@pytest.mark.integration
def test_noise_detection_and_unusual_frames_never_reopen_the_port(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """LD2410C background-noise detection sends target states 4-6 for as long as
    it measures (here > silence_timeout_s): valid frames, published, "no target"
    for presence, and no reopening of the port. Nor do well-formed frames with a
    state nobody knows (9): the line works, the content is unusual."""
    phase = Phase(standing(0.0, random.Random()))
    sensor = sensors(phase)
    frames = Collector(probe, keys.RADAR_FRAMES)
    presence = Collector(probe, keys.PRESENCE)
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    bridge = spawn("radar-bridge", "--sensor", sensor.path)
    spawn("radar-presence", "--absence-hold-s", "0.5")
    presence.wait_for(lambda v: v.presence_state == IN, 30, "IN_RANGE")

    phase.target = Target(p.STATE_NOISE_DETECTING)
    measuring = m.now_ns()
    presence.wait_for(lambda v: v.presence_state == OUT, 30, "OUT_OF_RANGE while measuring noise")
    retry_until(lambda: sum(f.target_state == m.TargetState.NOISE_DETECTING
                            for msg in frames.messages for f in msg.sensors) >= 40, 30,
                what="4 s of NOISE_DETECTING frames published")
    d = diag.wait_for(lambda d: d.values.get("radar0.noise_detection") == "in progress", 20,
                      "noise detection in diagnostics")
    # Fresh data saying "no target", not a silent sensor.
    pd = pdiag.wait_for(lambda x: x.stamp_ns > measuring + 2e9, 20, "presence diagnostics")
    assert pd.level == "OK", pd

    phase.target = Target(9)  # framing intact, a state we do not know
    d = diag.wait_for(lambda d: int(d.values.get("radar0.unusual_frames") or 0) >= 40, 30,
                      "4 s of unusual frames counted")
    phase.target = Target(p.STATE_NOISE_DETECTION_SUCCEEDED)
    wait_more_frames(frames, 0, 5)
    phase.target = standing(0.0, random.Random())
    presence.wait_for(lambda v: v.presence_state == IN and v.stamp_ns > d.stamp_ns, 30,
                      "IN_RANGE again")
    last = diag.wait_for(lambda x: x.stamp_ns > d.stamp_ns, 20, "diagnostics after it all")
    assert int(last.values["reconnects"]) == 0, last  # type: ignore[arg-type]
    assert all(x.values.get("radar0.connected") is True for x in diag.messages
               if x.stamp_ns > presence.messages[0].stamp_ns), "the port was reopened"
    assert int(last.values["bad_frames"]) == 0  # type: ignore[arg-type]
    states = {f.target_state for msg in frames.messages for f in msg.sensors}
    assert {m.TargetState.NOISE_DETECTING, m.TargetState.NOISE_DETECTION_SUCCEEDED} <= states
    assert bridge.alive()


@pytest.mark.integration
def test_light_level_and_out_pin_only_from_firmware_that_has_them(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """V1.07 sends two bytes where V2.x has light level and OUT pin (a real
    module said "OUT pin 33"): the bridge asks the firmware at connect."""
    from buddybot.radar.sim import FIRMWARE_V2

    v1 = sensors("nobody", "ttyV1", aux_bytes=(120, 33))
    v2 = sensors("nobody", "ttyV2", firmware=FIRMWARE_V2, aux_bytes=(130, 1))
    odd = sensors("nobody", "ttyOdd", firmware=FIRMWARE_V2, aux_bytes=(140, 7))
    frames = Collector(probe, keys.RADAR_FRAMES)
    diag = Collector(probe, keys.DIAGNOSTICS, node="radar-bridge")
    spawn("radar-bridge", "--sensor", v1.path, "--sensor", v2.path, "--sensor", odd.path)
    for radar_id in (0, 1, 2):
        wait_more_frames(frames, radar_id, 5, 30)
    by_id = {f.radar_id: f for msg in frames.messages for f in msg.sensors}
    assert (by_id[0].light_level, by_id[0].out_pin) == (None, None)
    assert (by_id[1].light_level, by_id[1].out_pin) == (130, 1)
    assert (by_id[2].light_level, by_id[2].out_pin) == (140, None)
    assert by_id[0].moving_gate_energy is not None  # still engineering frames
    d = diag.wait_for(lambda d: int(d.values.get("radar2.bad_out_pin") or 0) >= 5, 20,
                      "refused OUT pins counted")
    assert d.values["radar0.firmware"] == "V1.07.22091615"
    assert d.values["radar1.firmware"] == "V2.04.23022511"
    assert d.values["radar0.bad_out_pin"] == 0 and d.values["radar1.bad_out_pin"] == 0
    # The firmware query ran inside enable/end configuration, and reporting resumed.
    for s in (v1, v2, odd):
        assert s.sim.commands[:3] == [p.CMD_ENABLE_CONFIG, p.CMD_READ_FIRMWARE,
                                      p.CMD_END_CONFIG]
        assert not s.sim.config_mode
