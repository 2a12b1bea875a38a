"""Helpers for tests and benchmarks: a real router, real service processes.

Shipped inside the package (as dimos does) so benchmarks and other
projects' integration tests can use them too. Nothing here mocks Zenoh:
the router is `buddybot router` on a free loopback port (or the same Zenoh
router opened in the test's own process), services are `buddybot run ...`
processes, and probes are real sessions.
"""

from __future__ import annotations

import base64
import fcntl
import os
import random
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import wave
from collections.abc import Callable, Iterator, Sequence
from datetime import UTC, datetime
from functools import partial
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import endpoints
from buddybot.runtime.node import Node
from buddybot.runtime.session import open_router

T = TypeVar("T")
LOOPBACK = "127.0.0.1"


class Closable(Protocol):
    def close(self) -> None: ...


C = TypeVar("C", bound=Closable)


def closed_afterwards(open_one: Callable[..., C]) -> Iterator[Callable[..., C]]:
    """A fixture's body (`yield from` it): yields a maker calling `open_one`, and
    closes everything it made, newest first, once the test is over."""
    made: list[C] = []

    def make(*args: Any, **kwargs: Any) -> C:
        made.append(one := open_one(*args, **kwargs))
        return one

    yield make
    for one in reversed(made):
        one.close()


PORTS_DIR = Path(tempfile.gettempdir()) / "buddybot-ports"
"""One lock file per port handed out: processes on one machine (pytest-xdist workers,
a second test run) never get the same port while the first one lives."""
_held_ports: dict[int, int] = {}
_random = random.Random()


def _port_range() -> tuple[int, int]:
    """Ports below the kernel's ephemeral range: no outgoing connection is given one,
    so a port found free is taken only by someone who asked for it by number."""
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768
    return 10_000, max(10_001, min(low, 65_536) - 1)


def free_port() -> int:
    """A TCP port on loopback that nothing listens on now and that no other process
    of this machine gets from this function while this one runs (a lock file kept
    open until the process ends)."""
    PORTS_DIR.mkdir(exist_ok=True)
    low, high = _port_range()
    for _ in range(1000):
        port = _random.randint(low, high)
        if port in _held_ports:
            continue
        fd = os.open(PORTS_DIR / str(port), os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            try:
                sock.bind((LOOPBACK, port))
            except OSError:
                os.close(fd)
                continue
        _held_ports[port] = fd
        return port
    raise RuntimeError(f"no free loopback port in {low}..{high} after 1000 tries")


def retry_until(
    check: Callable[[], T], timeout: float = 10.0, interval: float = 0.05, what: str = "condition"
) -> T:
    """Call `check` until it returns something truthy; raise TimeoutError after `timeout`.

    For discovery races: the event is waited for, never slept for.
    """
    end = time.monotonic() + timeout
    last_exc: Exception | None = None
    while True:
        try:
            value = check()
            if value:
                return value
        except Exception as exc:  # the check may raise until ready
            last_exc = exc
        if time.monotonic() > end:
            raise TimeoutError(f"{what} not met within {timeout} s (last error: {last_exc!r})")
        time.sleep(interval)


def wait_port(port: int, timeout: float = 60.0) -> None:
    def accepting() -> bool:
        with socket.create_connection((LOOPBACK, port), timeout=0.5):
            return True

    retry_until(accepting, timeout, what=f"port {port} accepting")


def _limit_files(limit: int) -> None:
    """In the child before exec: at most `limit` open descriptors."""
    resource.setrlimit(resource.RLIMIT_NOFILE, (limit, limit))


class Process:
    """A child process whose output goes to a log file; stopped on `stop()`."""

    def __init__(self, argv: Sequence[str], name: str, log_dir: Path | None = None,
                 env: dict[str, str] | None = None, nofile: int | None = None) -> None:
        """`nofile`: the child's descriptor limit (RLIMIT_NOFILE, soft and hard),
        to flood it without flooding the machine."""
        self.name = name
        self.argv = list(argv)
        folder = log_dir or Path(tempfile.mkdtemp(prefix="buddybot-test-"))
        folder.mkdir(parents=True, exist_ok=True)
        self.log_path = folder / f"{name}.log"
        self._log = self.log_path.open("wb")
        self.proc = subprocess.Popen(
            self.argv, stdout=self._log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})},
            start_new_session=True,
            preexec_fn=None if nofile is None else partial(_limit_files, nofile),
        )

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        if not self._log.closed:  # still readable after stop() (the spawn fixture prints it)
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def kill(self, signum: int = signal.SIGKILL) -> None:
        if self.alive():
            os.killpg(self.proc.pid, signum)
            self.proc.wait(10)

    def send_signal(self, signum: int) -> None:
        """Signal the process group without waiting (SIGSTOP/SIGCONT to freeze it)."""
        if self.alive():
            os.killpg(self.proc.pid, signum)

    def stop(self, timeout: float = 10.0) -> int | None:
        """SIGTERM, then SIGKILL after `timeout`; returns the exit status."""
        if self.alive():
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(10)
            except ProcessLookupError:
                pass
        self._log.close()
        return self.proc.returncode

    def wait_for_output(self, text: str, timeout: float = 15.0) -> str:
        def printed() -> str:
            output = self.output()
            return output if text in output else ""

        return retry_until(printed, timeout, what=f"{self.name} printing {text!r}")


def visitor(in_range: bool, person_id: int = 1, distance_m: float = 1.2,
            stamp_ns: int | None = None, held: bool = False,
            face: bool = False) -> m.PeopleState:
    """`people/state` as the people service shows one visitor: seen by the radar
    (`in_range`; by the camera too with `face`), missed by every sensor and not
    yet gone (`held`, seen_by NONE), or gone (neither: nobody present). What a
    test about the controller alone publishes instead of running `people`."""
    stamp = m.now_ns() if stamp_ns is None else stamp_ns
    if not (in_range or held):
        return m.PeopleState(stamp_ns=stamp, people=[])
    seen_by: m.SeenBy = ("BOTH" if face else "RADAR") if in_range else "NONE"
    person = m.Person(id=person_id, distance_m=distance_m, zone="PERSONAL",
                      seen_by=seen_by, zone_since_ns=stamp,
                      arrived_ns=stamp, engagement="NONE", engagement_since_ns=stamp)
    return m.PeopleState(stamp_ns=stamp, people=[person])


def write_tone(path: Path, seconds: float, hz: float = 440.0, rate: int = 48000,
               channels: int = 1, amplitude: float = 0.3) -> Path:
    """A sine-tone WAV (int16) of a known length, for sound tests and benchmarks."""
    t = np.arange(int(seconds * rate)) / rate
    mono = (amplitude * np.sin(2 * np.pi * hz * t) * 32767).astype("<i2")
    with wave.open(str(path), "wb") as out:
        out.setnchannels(channels)
        out.setsampwidth(2)
        out.setframerate(rate)
        out.writeframes(np.repeat(mono[:, None], channels, axis=1).tobytes())
    return path


def stop_and_report(processes: list[Process], tail: int = 4000) -> None:
    """Stop test processes (newest first) and print the end of each log, so a failing
    test shows what its services said."""
    for proc in reversed(processes):
        proc.stop()
        print(f"--- {proc.name} (exit {proc.proc.returncode}) ---\n{proc.output()[-tail:]}")


def stuck_websocket(port: int, path: str = "/ws?eye=both", timeout: float = 20.0
                    ) -> tuple[socket.socket, bytes]:
    """A WebSocket client that completes the handshake on 127.0.0.1:`port` and then
    never reads again (a frozen tab, or an attacker), with a small receive buffer so
    the server's sends back up quickly. Returns the socket and the response head;
    raises ConnectionError when the server closes during the handshake."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.settimeout(timeout)
    try:
        sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        sock.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                     "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                     f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode())
        head = b""
        while b"\r\n\r\n" not in head:  # the response head only, byte by byte
            byte = sock.recv(1)
            if not byte:
                raise ConnectionError(f"closed during the handshake: {head!r}")
            head += byte
    except OSError:
        sock.close()
        raise
    return sock, head


def paused_eye_page(browser: Any, port: int, width: int, height: int, eye: str = "both") -> Any:
    """The eye page of the renderer on `port` in a Playwright `browser`, with no blinks
    or saccades of its own, once it is ready, with its clock paused:
    `page.clock.run_for(ms)` steps it, so each frame is taken at an exact moment of an
    animation however busy the machine is.

    The page stops asking the server's time then: a pong read on a paused clock has
    a round trip of about 0 ms, so it would win, and the server clock estimate would
    jump by however far real time has run ahead, and the breath (on that clock) with
    it, in one frame."""
    page = browser.new_page(viewport={"width": width, "height": height})
    page.clock.install()
    page.goto(f"http://{LOOPBACK}:{port}/eyes?eye={eye}&blink=0&saccade=0")
    page.wait_for_function("window.eyes && window.eyes.ready && window.eyes.cur.calm < 0.002",
                           timeout=30_000)
    page.evaluate(NO_PINGS)
    page.clock.pause_at(clock_time(time.time() * 1000 + 1000))
    return page


def clock_time(epoch_ms: float) -> datetime:
    """A moment for Playwright's page clock. A datetime, which every Playwright release
    reads the same way: a bare number is milliseconds to some and seconds to others."""
    return datetime.fromtimestamp(epoch_ms / 1000, tz=UTC)


NO_PINGS = """() => {
  const send = WebSocket.prototype.send;
  const isPing = (data) => {
    try { return JSON.parse(data).topic === "ping"; } catch (e) { return false; }
  };
  WebSocket.prototype.send = function (data) {
    if (typeof data === "string" && isPing(data)) return;
    return send.call(this, data);
  };
}"""
"""The page's clock-sync pings (answered by `eyes.wire.Pong`) go unsent; all else is sent."""


def buddybot_argv(*args: str) -> list[str]:
    return [sys.executable, "-m", "buddybot", *args]


class Router(Process):
    """`buddybot router` on a free loopback port."""

    def __init__(self, port: int | None = None, log_dir: Path | None = None,
                 extra: Sequence[str] = ()) -> None:
        self.port = port or free_port()
        self.endpoint = f"tcp/{LOOPBACK}:{self.port}"
        super().__init__(buddybot_argv("router", "--listen", self.endpoint, *extra),
                         f"router-{self.port}", log_dir)
        wait_port(self.port)


class InProcessRouter:
    """The Zenoh router `buddybot router` serves, opened in this process on a free
    loopback port: what most tests need, without starting (and paying for) one
    more Python process each. A test that kills, restarts or reads the log of
    its router needs a `Router` process instead."""

    def __init__(self, port: int | None = None) -> None:
        self.port = port or free_port()
        self.endpoint = f"tcp/{LOOPBACK}:{self.port}"
        self._session = open_router([self.endpoint], settle_s=0)  # nothing to scout

    def stop(self, timeout: float = 10.0) -> None:
        """Close the router and wait until its port accepts no more connections."""
        self._session.close()
        retry_until(lambda: not endpoints.accepting(self.endpoint), timeout,
                    what=f"router port {self.port} closed")


def run_service(service: str, endpoint: str, *args: str, robot: str = "buddy",
                log_dir: Path | None = None, env: dict[str, str] | None = None,
                nofile: int | None = None) -> Process:
    """Start `buddybot run SERVICE --connect ENDPOINT ...` as a child process."""
    argv = buddybot_argv("run", service, "--connect", endpoint, "--robot", robot, *args)
    return Process(argv, f"{service}-{time.monotonic_ns()}", log_dir, env, nofile)


class Collector(Generic[T]):
    """Collects the messages a node receives on a topic, with waits on them."""

    def __init__(self, node: Node, topic: keys.Topic, /, **params: str) -> None:
        self.items: list[tuple[Any, str]] = []
        self._cond = threading.Condition()
        key_params: dict[str, Any] = params  # key parameters only (camera=..., device=...)
        node.subscribe(topic, self._on, **key_params)

    def _on(self, msg: Any, key: str) -> None:
        with self._cond:
            self.items.append((msg, key))
            self._cond.notify_all()

    @property
    def messages(self) -> list[Any]:
        with self._cond:
            return [msg for msg, _ in self.items]

    def wait_for(self, predicate: Callable[[Any], bool] = lambda _m: True,
                 timeout: float = 10.0, what: str = "message") -> Any:
        """The first message (oldest first) matching `predicate`, waiting for it."""
        end = time.monotonic() + timeout
        with self._cond:
            while True:
                for msg, _ in self.items:
                    if predicate(msg):
                        return msg
                left = end - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"no {what} within {timeout} s; got {len(self.items)}: "
                                       f"{[m for m, _ in self.items[-5:]]}")
                self._cond.wait(left)

    def wait_count(self, n: int, timeout: float = 10.0) -> list[Any]:
        end = time.monotonic() + timeout
        with self._cond:
            while len(self.items) < n:
                left = end - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"got {len(self.items)} of {n} messages in {timeout} s")
                self._cond.wait(left)
            return [msg for msg, _ in self.items]

    def clear(self) -> None:
        with self._cond:
            self.items.clear()


# --- web surfaces under attack -----------------------------------------------------------

SLOW_HEAD = b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: "
"""A request head that never ends (slow headers)."""


class HeldSockets:
    """`count` connections to `port` that each send `head` and then hold on,
    sending nothing more (a slow-headers flood); `close()` ends them all."""

    def __init__(self, port: int, count: int, head: bytes = SLOW_HEAD) -> None:
        self.socks: list[socket.socket] = []
        self.failed = 0
        for _ in range(count):
            sock = socket.socket()
            sock.settimeout(0.5)
            try:
                sock.connect((LOOPBACK, port))
                if head:
                    sock.sendall(head)
            except OSError:
                sock.close()
                self.failed += 1
                continue
            self.socks.append(sock)

    def open_count(self) -> int:
        """How many the server has not closed yet (a peek: 0 bytes read means closed)."""
        alive = 0
        for sock in self.socks:
            sock.setblocking(False)
            try:
                alive += sock.recv(1, socket.MSG_PEEK) != b""
            except BlockingIOError:
                alive += 1
            except OSError:
                pass
        return alive

    def close(self) -> None:
        for sock in self.socks:
            sock.close()
        self.socks.clear()


def http_status(port: int, path: str = "/", *, host: str | None = None,
                origin: str | None = None, websocket: bool = False,
                timeout: float = 10.0, keep: list[socket.socket] | None = None) -> int:
    """The status a raw HTTP/1.1 request gets (0: no answer within `timeout`),
    with the Host and Origin given (`host` None: 127.0.0.1:port); `websocket`:
    a WebSocket handshake. `keep`: the socket is left open there (a page that
    stays), else closed."""
    lines = [f"GET {path} HTTP/1.1", f"Host: {host or f'{LOOPBACK}:{port}'}"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    if websocket:
        lines += ["Upgrade: websocket", "Connection: Upgrade",
                  f"Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}",
                  "Sec-WebSocket-Version: 13", "Sec-WebSocket-Protocol: foxglove.sdk.v1"]
    sock = socket.create_connection((LOOPBACK, port), timeout=timeout)
    try:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        data = b""
        while b"\r\n" not in data:
            chunk = sock.recv(4096)
            if not chunk:
                break
            data += chunk
    except OSError:
        data = b""
    finally:
        if keep is None or not data:
            sock.close()
        else:
            keep.append(sock)
    parts = data.split(b" ", 2)
    return int(parts[1]) if len(parts) > 1 and parts[1].isdigit() else 0


class RecordingPublisher:
    """A publisher of a fake node: what is put lands in `out` (shared by its node)."""

    def __init__(self, out: list[Any]) -> None:
        self.out = out

    def put(self, msg: Any) -> None:
        self.out.append(msg)


class FakeDiagnostics:
    """The part of `Diagnostics` a service uses: counters, values and its status."""

    def __init__(self) -> None:
        self.values: dict[str, Any] = {}
        self.level, self.message = "OK", "running"

    def increment(self, name: str, by: int = 1) -> None:
        self.values[name] = self.values.get(name, 0) + by

    def set(self, level: str, message: str) -> None:
        self.level, self.message = level, message
