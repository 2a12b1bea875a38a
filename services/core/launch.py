"""`buddybot up`: the router plus every service, each its own process.

Children are started with the same Python (`python -m buddybot ...`), their
output is prefixed with the service name, a child that dies is restarted
with exponential backoff and reported, and one Ctrl-C (or SIGTERM) stops
them all: SIGTERM first, SIGKILL for any still alive after a grace period.

Two faults are guarded against. A supervisor killed with SIGKILL cannot stop
its children, so each child asks the kernel for SIGTERM when its parent dies
(`die_with_supervisor`, PR_SET_PDEATHSIG); without it the router and the nine
services lived on as orphans. And a second `up` on a port where a robot
already runs refuses to start instead of joining it (two robots on one bus,
with a status line counting the other robot's nodes as its own).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, field
from typing import IO

from buddybot.core import registry
from buddybot.core.backoff import Backoff
from buddybot.core.node import Node, zenoh_config
from buddybot.core.service import ServiceContext
from buddybot.core.status import StatusMonitor

log = logging.getLogger("buddybot.up")

GRACE_S = 5.0
BACKOFF_MIN_S = 1.0
BACKOFF_MAX_S = 30.0
STABLE_S = 30.0
NO_RESTART_STATUS = frozenset({2})
"""Exit statuses that restarting cannot fix: a bad option or config, or a node of
that name already running elsewhere (the same rule as `RestartPreventExitStatus=2`
in the systemd units)."""
SUPERVISOR_ENV = "BUDDYBOT_SUPERVISOR_PID"
"""Set in each child's environment to the pid of the `up` that started it."""
_PR_SET_PDEATHSIG = 1
# Variables systemd sets for the unit's main process only: a child of `up` that
# inherited them would answer for `up` (READY=1, watchdog pings).
_SYSTEMD_ONLY = ("NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID")


@dataclass
class RestartPolicy:
    """When to restart a child that exited: pure, so the rule is tested without processes.

    The delay starts at `min_s` and doubles with each quick crash up to `max_s`;
    a run of at least `stable_s` counts as healthy and starts the series again.
    An exit status in `no_restart` is final (restarting would fail the same way).
    """

    min_s: float = BACKOFF_MIN_S
    max_s: float = BACKOFF_MAX_S
    stable_s: float = STABLE_S
    no_restart: frozenset[int] = NO_RESTART_STATUS
    backoff: Backoff = field(init=False)

    def __post_init__(self) -> None:
        self.backoff = Backoff(self.min_s, self.max_s, stable_s=self.stable_s)

    def after_exit(self, status: int | None, ran_s: float) -> float | None:
        """Seconds to wait before the restart, or None: do not restart."""
        if status in self.no_restart:
            return None
        return self.backoff.after_run(ran_s)


def die_with_supervisor(env: MutableMapping[str, str]) -> bool:
    """In a child of `up`, first thing: have the kernel send SIGTERM when `up` dies.

    The child sets this itself rather than through `preexec_fn`, which runs
    Python between fork and exec in a multi-threaded parent (output pumps,
    Zenoh) and can deadlock there. The price is a short window, from exec to
    this call, in which the parent could die unnoticed; comparing the parent's
    pid with the one `up` put in the environment closes it. PR_SET_PDEATHSIG
    fires when the *thread* that forked us ends, so `up` starts every child
    from its main thread, which lives as long as `up` does.

    SIGTERM rather than SIGKILL: the child leaves the way Ctrl-C makes it
    leave (the eye renderer closes its kiosk browsers, the player its device),
    which takes about two seconds for the whole robot.

    Returns False when the supervisor is already gone (the caller exits).
    Without the variable (not started by `up`) nothing is done.
    """
    raw = env.pop(SUPERVISOR_ENV, "")  # not inherited by our own children
    if not raw.isdigit():
        return True
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
            log.warning("prctl(PR_SET_PDEATHSIG) failed: %s", os.strerror(ctypes.get_errno()))
    return os.getppid() == int(raw)


def child_env(env: Mapping[str, str], supervisor_pid: int) -> dict[str, str]:
    """The environment of a child of `up`."""
    out = {k: v for k, v in env.items() if k not in _SYSTEMD_ONLY}
    out.update(PYTHONUNBUFFERED="1")
    out[SUPERVISOR_ENV] = str(supervisor_pid)
    return out


def connect_endpoint(listen: str) -> str:
    """Where local services reach a router listening on `listen`."""
    proto, _, addr = listen.partition("/")
    host, _, port = addr.rpartition(":")
    if host in ("0.0.0.0", "[::]", ""):
        host = "127.0.0.1"
    return f"{proto}/{host}:{port}"


def _host_port(endpoint: str) -> tuple[str, int]:
    _, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    return host.strip("[]"), int(port)


def accepting(endpoint: str) -> bool:
    """Whether something accepts TCP connections on `endpoint` right now."""
    try:
        with socket.create_connection(_host_port(endpoint), timeout=0.5):
            return True
    except (OSError, ValueError):
        return False


def wait_for_port(endpoint: str, timeout: float, stop: threading.Event) -> bool:
    """True once a TCP endpoint accepts connections."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and not stop.is_set():
        if accepting(endpoint):
            return True
        time.sleep(0.1)
    return False


def probe_nodes(endpoint: str, timeout_s: float = 3.0) -> list[str] | None:
    """Live BuddyBot nodes (`robot/node`) behind a Zenoh router at `endpoint`,
    or None when no Zenoh router answers there."""
    config = zenoh_config(connect=[endpoint])
    config.insert_json5("connect/timeout_ms", str(int(timeout_s * 1000)))
    try:
        # A probe: it must not show up in the very list it asks for.
        probe = Node("up-probe", connect=[endpoint], config=config, probe=True)
    except Exception:  # ConnectionError: not a Zenoh router, or it would not talk to us (TLS)
        return None
    with probe:
        return sorted(probe.node_instances(all_robots=True, timeout=timeout_s))


def busy_message(listen: str, nodes: list[str] | None) -> str:
    """The one line `up` prints when its router's port is taken."""
    if nodes is None:
        who = "something that does not answer as a Zenoh router listens there"
    elif nodes:
        who = f"a Zenoh router answers there, with live nodes: {', '.join(nodes)}"
    else:
        who = "a Zenoh router answers there (no live BuddyBot nodes)"
    return (f"buddybot up: {listen} is already in use: {who}. A robot may already be "
            "running: stop it first, or give --listen another port. Nothing started.")


@dataclass
class Child:
    """One supervised process."""

    name: str
    argv: list[str]
    policy: RestartPolicy = field(default_factory=RestartPolicy)
    given_up: bool = False
    proc: subprocess.Popen[bytes] | None = None
    started: float = 0.0
    next_start: float = 0.0
    restarts: int = 0
    threads: list[threading.Thread] = field(default_factory=list)

    def start(self, out: IO[str], lock: threading.Lock) -> None:
        # The child's PR_SET_PDEATHSIG watches the thread that forks it: only the
        # main thread lives as long as `up` (see die_with_supervisor).
        if threading.current_thread() is not threading.main_thread():
            raise RuntimeError("children of `up` must be started from its main thread")
        env = child_env(os.environ, os.getpid())
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
    for endpoint in listen:
        local = connect_endpoint(endpoint)
        if local.startswith(("tcp/", "tls/")) and accepting(local):
            print(busy_message(endpoint, probe_nodes(local)), file=sys.stderr, flush=True)
            return 1
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
    """The status monitor of `up`, owning its probe node."""

    def session_close(self) -> None:
        """Close the probe node (after `close()`, which ends the subscriptions)."""
        self.node.close()


def _monitor(ctx: ServiceContext, connect: str, expected: list[str]) -> _Monitor | None:
    """A status probe on our own router; None if it cannot be had (status is optional).

    The probe shares `ctx.stop`, so Ctrl-C still interrupts its wait for the
    router (closing it sets `ctx.stop`, which `up` has set by then anyway)."""
    if ctx.args.status_period <= 0:
        return None
    try:
        node = Node("up-status", robot=ctx.robot, connect=[connect], stop_event=ctx.stop,
                    probe=True)
    except ConnectionError as exc:
        log.warning("no status line: %s", exc)
        return None
    except KeyboardInterrupt:  # stopped while waiting for the router
        return None
    return _Monitor(node, expected)


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
            if child.proc is None or child.given_up or child.alive():
                continue
            if child.next_start == 0.0:
                code = child.proc.returncode
                delay = child.policy.after_exit(code, now - child.started)
                if delay is None:
                    child.given_up = True
                    log.error("%s exited with status %s (bad option or config, or a node of "
                              "that name already runs): not restarting it; the others keep "
                              "running", child.name, code)
                    continue
                child.next_start = now + delay
                log.warning("%s exited with status %s; restarting in %.0f s",
                            child.name, code, delay)
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
