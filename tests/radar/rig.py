"""The radar test rig: scripted scenes for simulated LD2410s, a stream server
playing radar bytes over TCP (an ESP32's), and waits on what the bridge
publishes (frames per sensor, diagnostics values)."""

from __future__ import annotations

import contextlib
import random
import socket
import threading
from collections.abc import Callable

import serial

from buddybot.contract import messages as m
from buddybot.radar.scenarios import NOBODY, Scenario, Target
from buddybot.radar.sim import PtySensor
from buddybot.tools.testing import LOOPBACK, Collector, retry_until


class Gated:
    """A scenario that shows nobody until `go()`, then plays `inner` from its start."""

    def __init__(self, inner: Scenario) -> None:
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
