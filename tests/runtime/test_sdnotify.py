"""sd_notify: readiness and watchdog pings, on a real AF_UNIX datagram socket.

systemd is not needed: the test binds the socket systemd would bind and reads
what the service sends. The process test checks the two promises the units rely
on: READY=1 only once the node is on the bus, and pings that stop when the
process stops.
"""

from __future__ import annotations

import os
import signal
import socket
import uuid
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from buddybot.runtime.sdnotify import Notifier, socket_address, watchdog_period_s
from buddybot.supervisor import router as router_module
from buddybot.tools.testing import (
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
    run_service,
    stop_and_report,
)


@pytest.fixture
def notify_socket(tmp_path: Path) -> Iterator[tuple[socket.socket, str]]:
    """A datagram socket standing in for systemd's, and its `$NOTIFY_SOCKET` value."""
    path = tmp_path / "notify"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    yield sock, str(path)
    sock.close()


def receive(sock: socket.socket, timeout: float) -> str | None:
    """The next datagram, or None when nothing arrives within `timeout`."""
    sock.settimeout(timeout)
    try:
        return sock.recv(4096).decode()
    except TimeoutError:
        return None


def receive_until(sock: socket.socket, text: str, timeout: float) -> list[str]:
    """Datagrams up to and including the first containing `text`."""
    got: list[str] = []
    while True:
        msg = receive(sock, timeout)
        assert msg is not None, f"no {text!r} within {timeout} s; got {got}"
        got.append(msg)
        if text in msg:
            return got


# --- pure parts ----------------------------------------------------------------------


def test_socket_address_forms() -> None:
    assert socket_address(None) is None
    assert socket_address("") is None
    assert socket_address("/run/systemd/notify") == "/run/systemd/notify"
    assert socket_address("@buddy/notify") == b"\0buddy/notify"  # abstract namespace
    assert socket_address("relative/path") is None  # not something systemd sets: ignored
    assert socket_address("vsock:2:1234") is None


def test_watchdog_period_is_half_the_timeout_and_only_for_us() -> None:
    assert watchdog_period_s({"WATCHDOG_USEC": "10000000"}, pid=42) == 5.0
    assert watchdog_period_s({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": "42"}, 42) == 5.0
    assert watchdog_period_s({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": "7"}, 42) is None
    assert watchdog_period_s({}, 42) is None
    assert watchdog_period_s({"WATCHDOG_USEC": "0"}, 42) is None
    assert watchdog_period_s({"WATCHDOG_USEC": "ten"}, 42) is None
    assert watchdog_period_s({"WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "x"}, 42) is None


# --- a real socket -------------------------------------------------------------------


def test_ready_and_watchdog_reach_a_path_socket(notify_socket: tuple[socket.socket, str]) -> None:
    sock, path = notify_socket
    notifier = Notifier.from_env({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "4000000"})
    assert notifier.enabled and notifier.watchdog_s == 2.0
    assert notifier.ready("node x up")
    assert receive(sock, 5) == "READY=1\nSTATUS=node x up"
    assert notifier.watchdog()
    assert receive(sock, 5) == "WATCHDOG=1"
    assert notifier.stopping()
    assert receive(sock, 5) == "STOPPING=1"
    notifier.close()


def test_abstract_namespace_socket() -> None:
    name = f"buddybot-test-{uuid.uuid4().hex}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(b"\0" + name.encode())
        notifier = Notifier.from_env({"NOTIFY_SOCKET": "@" + name})
        assert notifier.ready()
        assert receive(sock, 5) == "READY=1"
        notifier.close()


def test_without_systemd_nothing_is_sent_and_nothing_fails(tmp_path: Path) -> None:
    quiet = Notifier.from_env({})
    assert not quiet.enabled and quiet.watchdog_s is None
    assert quiet.ready() is False and quiet.watchdog() is False
    # A socket that went away (systemd restarting) is not an error for the service.
    gone = Notifier.from_env({"NOTIFY_SOCKET": str(tmp_path / "nobody-listens")})
    assert gone.enabled
    assert gone.ready() is False
    assert gone.watchdog() is False
    gone.close()


# --- real processes ------------------------------------------------------------------


@pytest.mark.integration
def test_service_is_ready_once_on_the_bus_and_pings_only_while_running(
    notify_socket: tuple[socket.socket, str], tmp_path: Path
) -> None:
    """READY=1 waits for the router; pings stop while the process is stopped."""
    sock, path = notify_socket
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env = {"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "1000000"}  # a ping every 0.5 s
    procs: list[Process] = []
    try:
        service = run_service("radar-presence", endpoint, log_dir=tmp_path, env=env)
        procs.append(service)
        # No router yet: the service waits, and must not claim to be ready.
        service.wait_for_output("waiting for the Zenoh router", 60)
        assert receive(sock, 1.0) is None
        procs.insert(0, Router(port, tmp_path))
        got = receive_until(sock, "READY=1", 60)
        assert got[-1].startswith("READY=1\nSTATUS=node radar-presence up")
        assert receive_until(sock, "WATCHDOG=1", 10)
        assert receive_until(sock, "WATCHDOG=1", 10)

        # A process that does not run (here: SIGSTOP) sends nothing; systemd would
        # kill and restart it after WatchdogSec.
        os.kill(service.pid, signal.SIGSTOP)
        retry_until(lambda: psutil.Process(service.pid).status() == psutil.STATUS_STOPPED,
                    10, what="service stopped")
        while receive(sock, 0.2) is not None:  # pings sent before it stopped
            pass
        assert receive(sock, 3.0) is None, "a stopped process must not ping"
        os.kill(service.pid, signal.SIGCONT)
        assert receive_until(sock, "WATCHDOG=1", 10)
    finally:
        stop_and_report(procs)


@pytest.mark.integration
@pytest.mark.skipif("sdnotify" not in Path(router_module.__file__).read_text(),
                    reason="services/supervisor/router.py does not call sdnotify yet")
def test_router_is_ready_once_listening_and_pings(
    notify_socket: tuple[socket.socket, str], tmp_path: Path
) -> None:
    sock, path = notify_socket
    port = free_port()
    env = {"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "1000000"}
    router = Process(buddybot_argv("router", "--listen", f"tcp/127.0.0.1:{port}"),
                     "router", tmp_path, env)
    try:
        assert receive_until(sock, "READY=1", 60)
        with socket.create_connection(("127.0.0.1", port), timeout=5):
            pass  # ready means listening
        assert receive_until(sock, "WATCHDOG=1", 10)
    finally:
        stop_and_report([router])
