"""`buddybot up`: the router plus every service, each its own process.

Children are started with the same Python (`python -m buddybot ...`), their
output is prefixed with the service name, a child that dies is restarted
with exponential backoff and reported, and one Ctrl-C (or SIGTERM) stops
them all: SIGTERM first, SIGKILL for any still alive after a grace period.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from typing import IO

from buddybot.core import registry
from buddybot.core.node import open_session, zenoh_config
from buddybot.core.service import ServiceContext
from buddybot.core.status import StatusMonitor

log = logging.getLogger("buddybot.up")

GRACE_S = 5.0
BACKOFF_MIN_S = 1.0
BACKOFF_MAX_S = 30.0
STABLE_S = 30.0


def connect_endpoint(listen: str) -> str:
    """Where local services reach a router listening on `listen`."""
    proto, _, addr = listen.partition("/")
    host, _, port = addr.rpartition(":")
    if host in ("0.0.0.0", "[::]", ""):
        host = "127.0.0.1"
    return f"{proto}/{host}:{port}"


def wait_for_port(endpoint: str, timeout: float, stop: threading.Event) -> bool:
    """True once a TCP endpoint accepts connections."""
    _, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    host = host.strip("[]")
    end = time.monotonic() + timeout
    while time.monotonic() < end and not stop.is_set():
        try:
            with socket.create_connection((host, int(port)), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.1)
    return False


@dataclass
class Child:
    """One supervised process."""

    name: str
    argv: list[str]
    restart: bool = True
    proc: subprocess.Popen[bytes] | None = None
    started: float = 0.0
    backoff: float = BACKOFF_MIN_S
    next_start: float = 0.0
    restarts: int = 0
    threads: list[threading.Thread] = field(default_factory=list)

    def start(self, out: IO[str], lock: threading.Lock) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(
            self.argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=env, start_new_session=True,
        )
        self.started = time.monotonic()
        thread = threading.Thread(
            target=_pump, args=(self.name, self.proc, out, lock), daemon=True
        )
        thread.start()
        self.threads = [thread]

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def signal(self, signum: int) -> None:
        if self.alive():
            assert self.proc is not None
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(signum)


def _pump(name: str, proc: subprocess.Popen[bytes], out: IO[str], lock: threading.Lock) -> None:
    assert proc.stdout is not None
    width = 14
    for raw in iter(proc.stdout.readline, b""):
        line = raw.decode("utf-8", "replace").rstrip()
        with lock:
            out.write(f"[{name:<{width}}] {line}\n")
            out.flush()


def service_argv(name: str, ctx: ServiceContext, connect: str) -> list[str]:
    """Command line of one service under `up`: sim flags when no hardware is set."""
    args = ctx.args
    argv = [sys.executable, "-m", "buddybot", "run", name, "--connect", connect,
            "--robot", ctx.robot, "--log-level", args.log_level]
    if args.config:
        argv += ["--config", args.config]
    sim = args.sim
    if name == "radar-bridge" and (sim or not ctx.config.radar_bridge.sensors):
        argv.append("--sim")
    if name == "camera" and (sim or not ctx.config.camera.source):
        argv.append("--sim")
    if name == "eye-renderer" and args.no_browser:
        argv.append("--no-browser")
    return argv


def up(ctx: ServiceContext) -> int:
    """Run the whole robot on this machine until Ctrl-C."""
    args = ctx.args
    listen = args.listen or ["tcp/127.0.0.1:7447"]
    connect = connect_endpoint(listen[0])
    out, lock = sys.stdout, threading.Lock()
    router_argv = [sys.executable, "-m", "buddybot", "router", "--log-level", args.log_level]
    for endpoint in listen:
        router_argv += ["--listen", endpoint]
    router = Child("router", router_argv)
    children: list[Child] = []
    entries = registry.available_services()
    if args.only:
        entries = [e for e in entries if e.name in args.only]
    log.info("starting router on %s and %d services: %s", ", ".join(listen), len(entries),
             ", ".join(e.name for e in entries))
    router.start(out, lock)
    try:
        if not wait_for_port(connect, 15.0, ctx.stop):
            log.error("router did not come up on %s", connect)
            return 1
        for entry in entries:
            child = Child(entry.name, service_argv(entry.name, ctx, connect))
            child.start(out, lock)
            children.append(child)
        if any(e.name == "eye-renderer" for e in entries):
            port = ctx.config.eye_renderer.port
            log.info("eyes: http://127.0.0.1:%d/eyes?eye=both", port)
        monitor = _monitor(ctx, connect, [e.name for e in entries])
        try:
            _supervise([router, *children], ctx.stop, out, lock, monitor, args.status_period)
        finally:
            if monitor is not None:
                monitor.close()
                monitor.session_close()
    finally:
        _stop_all(children)  # services first, so they leave while the router is up
        _stop_all([router])
    return 0


class _Monitor(StatusMonitor):
    def session_close(self) -> None:
        self._session.close()


def _monitor(ctx: ServiceContext, connect: str, expected: list[str]) -> _Monitor | None:
    """A status session on our own router; None if it cannot be had (status is optional)."""
    if ctx.args.status_period <= 0:
        return None
    try:
        session = open_session(zenoh_config(connect=[connect]), ctx.stop)
    except ConnectionError as exc:
        log.warning("no status line: %s", exc)
        return None
    return None if session is None else _Monitor(session, ctx.robot, expected)


def _supervise(children: list[Child], stop: threading.Event, out: IO[str],
               lock: threading.Lock, monitor: _Monitor | None, period: float) -> None:
    next_status = time.monotonic() + period
    while not stop.wait(0.2):
        now = time.monotonic()
        if monitor is not None and now >= next_status:
            next_status = now + period
            line = monitor.line(sum(c.restarts for c in children))
            with lock:
                out.write(f"[{'status':<14}] {line}\n")
                out.flush()
        for child in children:
            if child.alive() or child.proc is None:
                if child.alive() and now - child.started > STABLE_S:
                    child.backoff = BACKOFF_MIN_S
                continue
            if child.next_start == 0.0:
                code = child.proc.returncode
                child.next_start = now + child.backoff
                log.warning("%s exited with status %s; restarting in %.0f s",
                            child.name, code, child.backoff)
                child.backoff = min(child.backoff * 2, BACKOFF_MAX_S)
            elif now >= child.next_start:
                child.restarts += 1
                child.next_start = 0.0
                log.info("restarting %s (restart %d)", child.name, child.restarts)
                child.start(out, lock)


def _stop_all(children: list[Child]) -> None:
    for child in children:
        child.signal(signal.SIGTERM)
    end = time.monotonic() + GRACE_S
    for child in children:
        if child.proc is None:
            continue
        try:
            child.proc.wait(max(0.1, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            log.warning("%s did not stop in %.0f s; killing it", child.name, GRACE_S)
            child.signal(signal.SIGKILL)
            child.proc.wait(5)
        for thread in child.threads:
            thread.join(1.0)
    log.info("all stopped")
