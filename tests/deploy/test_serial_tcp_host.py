"""The `serial_tcp` component built and run, on ESPHome's host platform.

ESPHome can build a configuration for Linux (`host:`), where a UART is a
device path and sockets are the kernel's. The test writes such a
configuration with our component (a pseudo-terminal as the radar's UART, a
free port on this machine), lets ESPHome generate the firmware source
offline, compiles and links it with g++ (no PlatformIO, no download) and
runs it: bytes written to the pseudo-terminal come out of the TCP port,
bytes sent to the port come out of the pseudo-terminal, a second client is
refused while the first keeps working, a client that comes back is served
again, and the ring buffer wraps around without a byte out of place. It is
the C++ the ESP32 runs, on
another socket layer (the same BSD calls; lwIP's on the ESP32) and another
UART driver.

Compiled objects are kept by the hash of their source, the headers next to
it, the compiler and its flags (beside the ESPHome venv when writable, ~2 MB:
the first run compiles ESPHome's ~35 files, ~1 min of CPU; later runs only
the configuration's own main.cpp and what changed). Skipped without ESPHome
or g++.
"""

from __future__ import annotations

import hashlib
import os
import pty
import secrets
import select
import shutil
import socket
import subprocess
import time
import tty
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from buddybot.tools.testing import LOOPBACK, free_port
from tests.deploy.test_esphome import FOLDER, esphome_command, offline_prefix

pytestmark = [pytest.mark.integration,  # one worker: the second test finds the
              pytest.mark.xdist_group("esphome_host")]  # first one's objects

FLAGS = ["-std=gnu++20", "-DUSE_HOST", "-DESPHOME_LOG_LEVEL=ESPHOME_LOG_LEVEL_DEBUG",
         "-Wno-sign-compare", "-Wno-unused-but-set-variable", "-Wno-unused-variable",
         "-fno-exceptions", "-O0"]
BUFFER = 64
HOST_YAML = """\
esphome:
  name: serial-tcp-host
host:
logger:
  level: DEBUG
uart:
  - id: radar_uart
    port: {uart}
    baud_rate: 230400
external_components:
  - source: {{type: local, path: components}}
    components: [serial_tcp]
serial_tcp:
  - id: radar_server
    uart_id: radar_uart
    port: {port}
    buffer_size: {buffer}
    max_clients: 1
"""


def object_cache(tmp_path: Path) -> Path:
    """Beside the ESPHome venv when that is writable (kept between runs), else tmp."""
    venv = Path(esphome_command() or "").resolve().parent.parent
    if venv.is_dir() and os.access(venv, os.W_OK):
        cache = venv / "serial-tcp-host-objects"
        cache.mkdir(exist_ok=True)
        return cache
    return tmp_path / "objects"


def build(tmp_path: Path, uart: str, port: int) -> Path:
    """Generate the host firmware with ESPHome, compile and link it; its path."""
    command = esphome_command()
    if command is None:
        pytest.skip("ESPHome is not installed: scripts/esphome.sh installs it")
    gxx = shutil.which("g++")
    if gxx is None:
        pytest.skip("no g++ to build the host firmware")
    shutil.copytree(FOLDER / "components", tmp_path / "components")
    (tmp_path / "host.yaml").write_text(HOST_YAML.format(uart=uart, port=port, buffer=BUFFER))
    done = subprocess.run([*offline_prefix(), command, "compile", "--only-generate", "host.yaml"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    build_dir = tmp_path / ".esphome" / "build" / "serial-tcp-host"
    src = build_dir / "src"
    headers = hashlib.sha256()
    for header in sorted(src.rglob("*.h")):
        headers.update(str(header.relative_to(src)).encode() + b"\0" + header.read_bytes())
    version = subprocess.run([gxx, "-dumpfullversion"], capture_output=True, text=True,
                             timeout=30, check=True).stdout
    cache = object_cache(tmp_path)
    cache.mkdir(exist_ok=True)

    def compile_one(source: Path) -> Path:
        key = hashlib.sha256(headers.digest() + " ".join([gxx, version, *FLAGS]).encode()
                             + str(source.relative_to(src)).encode() + source.read_bytes())
        # main.cpp holds this run's port and device: never the same twice, not kept
        folder = tmp_path if source == src / "main.cpp" else cache
        target = folder / f"{key.hexdigest()[:32]}.o"
        if not target.exists():
            partial = folder / f"{target.stem}.{secrets.token_hex(4)}.tmp.o"
            made = subprocess.run([gxx, *FLAGS, f"-I{src}", "-c", str(source), "-o", str(partial)],
                                  capture_output=True, text=True, timeout=600, check=False)
            assert made.returncode == 0, f"{source.relative_to(src)}:\n{made.stderr}"
            partial.replace(target)  # atomic: a parallel run never reads half an object
        return target

    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        objects = list(pool.map(compile_one, sorted(src.rglob("*.cpp"))))
    firmware = build_dir / "firmware"
    linked = subprocess.run([gxx, *map(str, objects), "-o", str(firmware), "-lpthread"],
                            capture_output=True, text=True, timeout=300, check=False)
    assert linked.returncode == 0, linked.stderr
    return firmware


class Log:
    """The firmware's log, read line by line as it comes (no sleeping). Its
    output is a terminal of its own: to a pipe, printf would hold the lines
    back in a buffer."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.seen: list[str] = []
        self.pending = b""

    def wait_for(self, text: str, timeout: float = 10.0) -> str:
        deadline = _now() + timeout
        while True:
            for line in self.seen:
                if text in line:
                    self.seen.remove(line)
                    return line
            left = deadline - _now()
            ready, _, _ = select.select([self.fd], [], [], max(left, 0))
            if not ready:
                raise AssertionError(f"no {text!r} in the firmware's log:\n" + "\n".join(self.seen))
            try:
                chunk = os.read(self.fd, 4096)
            except OSError:  # EIO: the terminal's other side is closed
                chunk = b""
            if not chunk:
                raise AssertionError(f"the firmware stopped before {text!r}:\n"
                                     + "\n".join(self.seen))
            self.pending += chunk
            *lines, self.pending = self.pending.split(b"\n")
            self.seen += [line.decode(errors="replace") for line in lines]


def _now() -> float:
    return time.monotonic()


def recv_exactly(sock: socket.socket, count: int) -> bytes:
    data = b""
    while len(data) < count:
        chunk = sock.recv(count - len(data))
        assert chunk, f"connection closed after {data!r}"
        data += chunk
    return data


def read_pty(master: int, count: int, timeout: float = 5.0) -> bytes:
    data = b""
    deadline = _now() + timeout
    while len(data) < count:
        ready, _, _ = select.select([master], [], [], max(deadline - _now(), 0))
        assert ready, f"the UART got only {data!r}"
        data += os.read(master, count - len(data))
    return data


@pytest.fixture
def running(tmp_path: Path) -> Iterator[tuple[int, int, Log]]:
    """The host firmware running: (pty master = the radar's side, TCP port, log)."""
    master, slave = pty.openpty()
    tty.setraw(master)
    uart = f"/tmp/bb-serial-tcp-{secrets.token_hex(6)}"  # ESPHome wants /dir/name
    os.symlink(os.ttyname(slave), uart)
    port = free_port()
    log_master, log_slave = pty.openpty()
    process = None
    try:
        firmware = build(tmp_path, uart, port)
        process = subprocess.Popen([str(firmware)], stdin=subprocess.DEVNULL, stdout=log_slave,
                                   stderr=log_slave, cwd=tmp_path)
        log = Log(log_master)
        log.wait_for(f"Port: {port}")  # dump_config: the server is listening
        yield master, port, log
    finally:
        if process is not None:
            process.terminate()
            process.wait(timeout=10)
        os.unlink(uart)
        for fd in (master, slave, log_master, log_slave):
            os.close(fd)


def connect(port: int) -> socket.socket:
    sock = socket.create_connection((LOOPBACK, port), timeout=5)
    sock.settimeout(5)
    return sock


def test_bytes_go_both_ways_and_a_second_client_is_refused(
        running: tuple[int, int, Log]) -> None:
    master, port, log = running
    with connect(port) as bridge:
        log.wait_for("client connected (1)")
        report = bytes.fromhex("F4F3F2F10D00020000000000000000000000F8F7F6F5")  # LD2410 frame
        os.write(master, report)
        assert recv_exactly(bridge, len(report)) == report
        command = bytes.fromhex("FDFCFBFA0400FF00010004030201")  # enable configuration
        bridge.sendall(command)
        assert read_pty(master, len(command)) == command

        with connect(port) as second:
            log.wait_for("refused a client (1 of 1 connected)")
            assert second.recv(16) == b"", "a second reader is closed at once"
        os.write(master, report)
        assert recv_exactly(bridge, len(report)) == report, "the first reader keeps the radar"

    log.wait_for("client gone (closed by the client, errno 0)")
    with connect(port) as again:  # the bridge reconnecting after a drop
        log.wait_for("client connected (1)")
        os.write(master, report)
        assert recv_exactly(again, len(report)) == report
        again.sendall(command)
        assert read_pty(master, len(command)) == command


def test_the_ring_wraps_around_without_a_byte_out_of_place(
        running: tuple[int, int, Log]) -> None:
    """The ring is 64 bytes here: 4 KB through it, half a ring at a time,
    wraps it 64 times; every byte arrives, in order."""
    master, port, log = running
    with connect(port) as bridge:
        log.wait_for("client connected (1)")
        burst = bytes(range(256)) * 16
        got = b""
        for start in range(0, len(burst), BUFFER // 2):
            os.write(master, burst[start:start + BUFFER // 2])
            got += recv_exactly(bridge, min(BUFFER // 2, len(burst) - start))
        assert got == burst
