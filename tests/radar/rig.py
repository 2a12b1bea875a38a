"""The radar test rig: scripted scenes for simulated LD2410s, a stream server
playing radar bytes over TCP (an ESP32's), waits on what the bridge publishes
(frames per sensor, diagnostics values), and angle-radar targets as the bridge
would publish them."""

from __future__ import annotations

import contextlib
import math
import random
import socket
import threading
from collections.abc import Callable
from typing import Any

import serial
from hypothesis import strategies as st

from buddybot.contract import messages as m
from buddybot.radar import envelope, ld2410
from buddybot.radar.ld2450_sim import SimulatedLD2450
from buddybot.radar.sim import PtySensor, SimulatedLD2410
from buddybot.radar.sim_scene import NOBODY, Script, Target
from buddybot.tools.testing import LOOPBACK, Collector, retry_until


class Gated:
    """A scenario that shows nobody until `go()`, then plays `inner` from its start."""

    def __init__(self, inner: Script) -> None:
        self.inner = inner
        self.started: float | None = None
        self.sensor: PtySensor | None = None

    def __call__(self, t: float, rng: random.Random) -> Target:
        if self.started is None:
            return NOBODY
        return self.inner(t - self.started, rng)

    def go(self) -> None:
        assert self.sensor is not None
        self.started = self.sensor.scenario_time()


def standing(t: float, rng: random.Random) -> Target:
    """A person standing still 1.00 m away (STATIONARY at 100 cm)."""
    return Target(2, 100, 5, 100, 70, 100)


def frames_of(collector: Collector[m.LD2410TargetDataFrameArray], radar_id: int) -> int:
    return sum(1 for msg in collector.messages for f in msg.sensors if f.radar_id == radar_id)


def wait_more_frames(collector: Collector[m.LD2410TargetDataFrameArray], radar_id: int, n: int,
                     timeout: float = 20.0) -> None:
    start = frames_of(collector, radar_id)
    retry_until(lambda: frames_of(collector, radar_id) >= start + n, timeout,
                what=f"{n} more frames from radar {radar_id}")


def diag_value(msg: m.DiagnosticStatus, name: str) -> object:
    return msg.values.get(name)


def open_port(path: str) -> serial.Serial:
    """The serial port of a simulated sensor, as the bridge opens a real one."""
    return serial.serial_for_url(path, baudrate=256000, timeout=0.05)


def radar_target(x: float, y: float, speed: float = 0.0, slot: int = 0) -> m.RadarTarget:
    """An LD2450 target at (x forward, y left) metres in the camera's frame, the
    sensor mounted at the camera facing forward (its y axis = forward)."""
    return m.RadarTarget(slot=slot, x_m=-y, y_m=x, speed_mps=speed, resolution_m=0.36,
                         position=m.Point(x=x, y=y, z=0.0), bearing_rad=math.atan2(y, x),
                         distance_m=math.hypot(x, y))


def ack_of(data: bytes) -> envelope.Ack:
    """The one ACK in `data` (a simulator's answer; either model's envelope)."""
    [frame] = ld2410.Parser().feed(data)
    assert isinstance(frame, envelope.Ack)
    return frame


def cmd(frame: bytes) -> envelope.Command:
    """A command frame as a simulator receives it."""
    [command] = ld2410.Parser().feed(frame)
    assert isinstance(command, envelope.Command)
    return command


def check_any_chunking(make_parser: Callable[[], Any], stream: bytes,
                       frames: list[Any]) -> None:
    """A parser yields exactly `frames` from `stream` split at every byte boundary,
    and fed byte by byte (both models' parsers)."""
    for i in range(len(stream) + 1):
        parser = make_parser()
        got = parser.feed(stream[:i]) + parser.feed(stream[i:])
        assert got == frames, i
        assert parser.stats.bad_frames == 0
    parser = make_parser()
    assert [f for b in stream for f in parser.feed(bytes([b]))] == frames


def check_noisy_stream(sim: SimulatedLD2410 | SimulatedLD2450,
                       parser: envelope.FrameParser) -> None:
    """50 s of a simulator's noisy scenario (500 frames): most reach `parser`
    whole, some are bad, none breaks it (both models)."""
    reports = [f for i in range(500) for f in parser.feed(sim.report(i * 0.1, i * 0.1))]
    assert 400 < len(reports) < 500
    assert parser.stats.bad_frames > 0


MUTATIONS = ["intact", "intact", "truncate", "delete", "insert", "overwrite"]


def mutate(draw: Any, frame: bytes, noise: Any, structural: list[int]) -> tuple[bytes, str]:
    """One frame left intact or with exactly one mutation (for both models' fuzz tests):
    cut short, a byte deleted, noise inserted, or a structural byte (head, length,
    markers, tail: `structural` offsets) changed."""
    data = bytearray(frame)
    kind = draw(st.sampled_from(MUTATIONS))
    if kind == "truncate":
        data = data[: draw(st.integers(1, len(data) - 1))]
    elif kind == "delete":
        del data[draw(st.integers(0, len(data) - 1))]
    elif kind == "insert":
        at = draw(st.integers(1, len(data) - 1))
        data[at:at] = draw(noise)
    elif kind == "overwrite":
        at = draw(st.sampled_from(structural))
        data[at] = (data[at] + draw(st.integers(1, 255))) % 256
    return bytes(data), kind


def feed_in_cuts(parser: Any, data: bytes, cuts: list[int]) -> list[Any]:
    """Everything `parser` yields from `data` fed in pieces split at `cuts`."""
    got: list[Any] = []
    last = 0
    for cut in [*cuts, len(data)]:
        got += parser.feed(data[last:cut])
        last = cut
    return got


class StreamServer:
    """What an ESP32's stream server (or ser2net) is to the bridge: a TCP port on
    127.0.0.1 that sends a radar's bytes, one client at a time.

    `frame(n)` gives the n-th frame's bytes (n = 1, 2, ...: the radar goes on
    counting across connections, as a real one does while the ESP32 reboots);
    each is sent in two writes, so frames straddle TCP segments as they straddle
    the ESP32's UART reads. `sent` holds, per connection, the numbers of the
    frames sent whole. `drop()` closes the client's connection and keeps
    listening (Wi-Fi gone, server restarted); `reboot()` also closes the
    listening port, so connecting is refused until `come_back()` listens on
    the same port again.
    """

    def __init__(self, frame: Callable[[int], bytes], period_s: float = 0.1) -> None:
        self._frame = frame
        self._period_s = period_s
        self.server = socket.create_server((LOOPBACK, 0))
        self.port = self.server.getsockname()[1]
        self.url = f"socket://{LOOPBACK}:{self.port}"
        self.sent: list[list[int]] = []
        self.received = bytearray()  # what the client wrote (commands)
        self._next = 1
        self._drop = threading.Event()
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._idle = threading.Event()  # no client connected
        self.thread = threading.Thread(target=self._serve, name="stream-server", daemon=True)
        self.thread.start()

    @property
    def connections(self) -> int:
        return len(self.sent)

    def _serve(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                server = self.server
            if server is None:  # rebooting: nothing listens
                self._idle.set()
                self._stop.wait(0.05)
                continue
            server.settimeout(0.1)
            try:
                conn, _ = server.accept()
            except (TimeoutError, OSError):
                self._idle.set()
                continue
            self._idle.clear()
            self._drop.clear()
            self.sent.append([])
            with conn:
                self._stream(conn, self.sent[-1])
            self._idle.set()

    def _stream(self, conn: socket.socket, sent: list[int]) -> None:
        conn.setblocking(False)
        while not (self._stop.is_set() or self._drop.is_set()):
            data = self._frame(self._next)
            half = len(data) // 2
            try:
                conn.sendall(data[:half])
                conn.sendall(data[half:])
            except OSError:
                return
            sent.append(self._next)
            self._next += 1
            with contextlib.suppress(BlockingIOError, OSError):
                self.received += conn.recv(4096)
            self._stop.wait(self._period_s)

    def drop(self) -> None:
        """Close the client's connection at a frame boundary; keep listening."""
        self._idle.clear()
        self._drop.set()
        retry_until(self._idle.is_set, 10, what="connection closed")

    def reboot(self) -> None:
        """Close the connection and the listening port: connecting is refused."""
        with self._lock:
            server, self.server = self.server, None
        assert server is not None
        self.drop()
        server.close()

    def come_back(self) -> None:
        """Listen again on the same port (the ESP32 is up again)."""
        with self._lock:
            self.server = socket.create_server((LOOPBACK, self.port))

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)
        with self._lock:
            if self.server is not None:
                self.server.close()
