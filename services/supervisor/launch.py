"""`buddybot up`: the router plus every service, each its own process.

Children are started with the same Python (`python -m buddybot ...`), their
output is prefixed with the service name, a child that dies is restarted
with exponential backoff and reported, and one Ctrl-C (or SIGTERM) stops
them all: SIGTERM first, SIGKILL for any still alive after a grace period.

Two faults are guarded against. A supervisor killed with SIGKILL cannot stop
its children, so each child asks the kernel for SIGTERM when its parent dies
(`die_with_supervisor`, PR_SET_PDEATHSIG); without it the router and the nine
services would live on as orphans. And a second `up` on a port where a robot
already runs refuses to start instead of joining it (two robots on one bus,
with a status line counting the other robot's nodes as its own). Our router is
ready only when it says so itself (sd_notify READY=1 on a socket of ours), so a
port taken between the check and the bind stops `up` instead of being joined,
and so does a port taken while the router restarts. The web services' ports
are tried before anything starts too (`ports.py`), and their addresses are
printed only once they say they serve.

The options are validated into an `UpPlan` before anything starts: an unknown
`--only` name is a usage error (exit 2), `--connect` joins a running router
instead of starting one, `[zenoh] config_file` (the TLS profile) is handed to
the router and to every child.
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
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import IO

from buddybot.runtime import enabled, endpoints, registry
from buddybot.runtime.backoff import Backoff
from buddybot.runtime.config import DEFAULT_ENDPOINT, ConfigBase, resolve_path
from buddybot.runtime.errors import EXIT_FAILURE, EXIT_USAGE, UsageError
from buddybot.runtime.node import Node
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.supervised import SUPERVISOR_ENV
from buddybot.sim.scenario import ScenarioError, load
from buddybot.sim.settings import SimSettings
from buddybot.supervisor import ports
from buddybot.supervisor.status import StatusMonitor
from buddybot.tools import doctor

log = logging.getLogger("buddybot.up")

GRACE_S = 5.0
BACKOFF_MIN_S = 1.0
BACKOFF_MAX_S = 30.0
STABLE_S = 30.0
PROBE_TIMEOUT_S = 3.0
"""How long the look at a taken port waits for a Zenoh router to answer there."""
NO_RESTART_STATUS = frozenset({2})
"""Exit statuses that restarting cannot fix: a bad option or config, or a node of
that name already running elsewhere (the same rule as `RestartPreventExitStatus=2`
in the systemd units)."""
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


def child_env(env: Mapping[str, str], supervisor_pid: int) -> dict[str, str]:
    """The environment of a child of `up`."""
    out = {k: v for k, v in env.items() if k not in _SYSTEMD_ONLY}
    out.update(PYTHONUNBUFFERED="1")
    out[SUPERVISOR_ENV] = str(supervisor_pid)
    return out


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
    notify: bool = False
    """Give the child its own sd_notify socket: `ready` is set when it says READY=1
    (the router does once its listening socket is bound), whatever its log level."""
    ready: threading.Event = field(default_factory=threading.Event)
    on_line: Callable[[str], None] | None = None
    """Called with each line of the child's output (after it is shown)."""

    def start(self, out: IO[str], lock: threading.Lock) -> None:
        # The child's PR_SET_PDEATHSIG watches the thread that forks it: only the
        # main thread lives as long as `up` (see die_with_supervisor).
        if threading.current_thread() is not threading.main_thread():
            raise RuntimeError("children of `up` must be started from its main thread")
        env = child_env(os.environ, os.getpid())
        self.ready.clear()
        listener = None
        if self.notify:
            listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            name = f"buddybot-up-{os.getpid()}-{self.name}-{self.restarts}-{time.monotonic_ns()}"
            listener.bind(b"\0" + name.encode())
            env["NOTIFY_SOCKET"] = "@" + name
        self.proc = subprocess.Popen(
            self.argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=env, start_new_session=True,
        )
        self.started = time.monotonic()
        thread = threading.Thread(
            target=_pump, args=(self.name, self.proc, out, lock, self.on_line), daemon=True
        )
        thread.start()
        self.threads = [thread]
        if listener is not None:
            waiter = threading.Thread(target=_await_ready, args=(listener, self.proc, self.ready),
                                      daemon=True)
            waiter.start()
            self.threads.append(waiter)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def signal(self, signum: int) -> None:
        if self.alive():
            assert self.proc is not None
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(signum)


def _pump(name: str, proc: subprocess.Popen[bytes], out: IO[str], lock: threading.Lock,
          on_line: Callable[[str], None] | None = None) -> None:
    assert proc.stdout is not None
    width = 14
    for raw in iter(proc.stdout.readline, b""):
        line = raw.decode("utf-8", "replace").rstrip()
        with lock:
            out.write(f"[{name:<{width}}] {line}\n")
            out.flush()
        if on_line is not None:
            on_line(line)


def _await_ready(listener: socket.socket, proc: subprocess.Popen[bytes],
                 ready: threading.Event) -> None:
    """Set `ready` when the child sends READY=1 on its sd_notify socket (see Child.notify);
    the socket is closed once it did, or once the child is gone."""
    listener.settimeout(0.2)
    with listener:
        while proc.poll() is None:
            try:
                data = listener.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                return
            if b"READY=1" in data.split(b"\n"):
                ready.set()
                return


@dataclass(frozen=True)
class AppLaunch:
    """One app of `[apps]`: its node name (also its log prefix) and the spec its
    runner is given (a relative FILE made absolute from the config's folder)."""

    name: str
    spec: str


def plan_apps(config: ConfigBase) -> list[AppLaunch]:
    """`[apps] run` as launches; the table was checked when the config was read."""
    out = []
    for spec in config.apps.specs():
        text = str(spec)
        if spec.kind == "file":
            path = resolve_path(config, spec.target).absolute()
            text = str(path) + (f":{spec.cls}" if spec.cls else "")
        out.append(AppLaunch(spec.default_name, text))
    return out


@dataclass
class UpPlan:
    """What `up` will do, decided (and validated) before anything starts."""

    entries: list[registry.Entry]
    listen: list[str]
    """Where our router listens; empty when joining a router (`--connect`)."""
    connect: list[str]
    """Where the services connect."""
    zenoh_file: str | None = None
    """The Zenoh file of `[zenoh] config_file` (TLS): every child's and every probe's."""
    router_file: str | None = None
    """The Zenoh file of our router: `[zenoh] router_config_file`, else `zenoh_file`."""
    service_args: dict[str, list[str]] = field(default_factory=dict)
    """Extra options per service (`--eye-port` -> eye-renderer's `--port`)."""
    apps: list[AppLaunch] = field(default_factory=list)
    """The apps of `[apps] run`, started after the services."""

    @property
    def joins(self) -> bool:
        return not self.listen


def default_listen(configured: list[str]) -> str:
    """Where `up`'s router listens when not told: the configured connect endpoint
    when it is on this machine's loopback (that is where the services look),
    else the default endpoint."""
    if configured and endpoints.endpoint_is_loopback(configured[0]):
        return configured[0]
    return DEFAULT_ENDPOINT


def select_services(only: list[str] | None, known: list[registry.Entry],
                    installed: list[registry.Entry]) -> list[registry.Entry]:
    """The services `--only` names (all installed ones without it).

    An unknown name is a UsageError naming it and the valid names: a typo such
    as `--only camra` must not start nothing and say nothing.
    """
    if not only:
        return [e for e in installed if not e.on_request]
    names = [e.name for e in known]
    unknown = [n for n in only if n not in names]
    if unknown:
        raise UsageError(f"--only: unknown service {', '.join(map(repr, unknown))} "
                         f"(valid: {', '.join(names)})")
    missing = [n for n in only if n not in {e.name for e in installed}]
    if missing:
        raise UsageError(f"--only: {', '.join(missing)} is not installed here")
    return [e for e in installed if e.name in only]


def requested(ctx: ServiceContext) -> list[registry.Entry]:
    """The on-request services `up` starts: those whose option was given
    (`--foxglove`, `--ros2`), and, without `--only`, those whose table says
    `enabled = true`. An asked-for service that is not installed is a UsageError."""
    chosen: list[registry.Entry] = []
    for entry in registry.SERVICES:
        if not entry.on_request:
            continue
        flag = entry.up_flag
        asked = flag is not None and getattr(ctx.args, flag.lstrip("-").replace("-", "_"), False)
        if not asked and not getattr(ctx.args, "only", None):
            asked = enabled.table_enables(entry, ctx.config)
        if not asked:
            continue
        if not entry.exists():
            raise UsageError(f"{flag or entry.name}: {entry.name} is not installed here")
        chosen.append(entry)
    return chosen


SIM_LEAD_S = 2.0
"""The simulated world starts this long after `up` plans it: its sensors are starting."""


def simulated(name: str, ctx: ServiceContext) -> bool:
    """Whether `up` runs this sensor service on the simulated world (`enabled.simulated`)."""
    return enabled.simulated(name, ctx.config, bool(ctx.args.sim))


def world_args(ctx: ServiceContext) -> list[str]:
    """The options that give every simulated sensor the same world and start.

    The scenario is loaded here, so a bad one stops `up` (exit 2) before
    anything starts, with the file's line and key."""
    settings = ctx.config.section(SimSettings)
    scenario = getattr(ctx.args, "scenario", None) or settings.scenario
    seed = getattr(ctx.args, "seed", None)
    try:
        load(scenario)
    except ScenarioError as exc:
        raise UsageError(f"--scenario: {exc}") from None
    argv = ["--scenario", scenario, "--sim-start",
            f"{(settings.start or time.time() + SIM_LEAD_S):.3f}"]
    return argv + (["--seed", str(seed)] if seed is not None else [])


def plan_up(ctx: ServiceContext) -> UpPlan:
    """Validate the options of `up` into a plan (UsageError: exit 2, nothing started)."""
    args = ctx.args
    only = getattr(args, "only", None)
    entries = select_services(only, list(registry.SERVICES), registry.available_services())
    for entry in requested(ctx):
        if not any(e.name == entry.name for e in entries):
            entries.append(entry)
    sensors = [e.name for e in entries if simulated(e.name, ctx)]
    if not sensors:  # a robot with its hardware: no simulated world, no truth
        entries = [e for e in entries if not e.simulation or (only and e.name in only)]
    joined = getattr(args, "connect", None)
    if joined and args.listen:
        raise UsageError("--connect joins a running router, --listen starts one: not both")
    if joined:
        listen: list[str] = []
        connect = list(joined)
    else:
        listen = list(args.listen or [default_listen(ctx.config.zenoh.connect)])
        connect = [endpoints.connect_endpoint(listen[0])]
    extra: dict[str, list[str]] = {}
    if getattr(args, "eye_port", None) is not None:
        extra["eye-renderer"] = ["--port", str(args.eye_port)]
        # The dashboard shows the eye page in a frame: it must point at the same port.
        extra["dashboard"] = ["--eye-port", str(args.eye_port)]
    if getattr(args, "dashboard_port", None) is not None:
        extra.setdefault("dashboard", []).extend(["--port", str(args.dashboard_port)])
    if sensors or any(e.simulation for e in entries):
        world = world_args(ctx)
        for name in [*sensors, *(e.name for e in entries if e.simulation)]:
            extra.setdefault(name, []).extend(world)
    zenoh = ctx.config.zenoh
    return UpPlan(entries, listen, connect, zenoh.config_file, zenoh.router_config_file
                  or zenoh.config_file, extra, plan_apps(ctx.config))


def service_argv(name: str, ctx: ServiceContext, connect: str | list[str],
                 extra: list[str] | None = None) -> list[str]:
    """Command line of one service under `up`: sim flags when no hardware is set."""
    args = ctx.args
    argv = [sys.executable, "-m", "buddybot", "run", name]
    argv += _child_options(ctx, [connect] if isinstance(connect, str) else connect)
    if simulated(name, ctx):
        argv.append("--sim")
    if name == "eye-renderer" and args.no_browser:
        argv.append("--no-browser")
    return argv + list(extra or [])


def app_argv(app: AppLaunch, ctx: ServiceContext, connect: list[str]) -> list[str]:
    """Command line of one app under `up`: its runner, named as `up` knows it."""
    argv = [sys.executable, "-m", "buddybot", "app", "run", app.spec, "--name", app.name]
    return argv + _child_options(ctx, connect)


def _child_options(ctx: ServiceContext, connect: list[str]) -> list[str]:
    """The common options every child of `up` gets: where, which robot, how verbose."""
    argv = []
    for endpoint in connect:
        argv += ["--connect", endpoint]
    argv += ["--robot", ctx.robot, "--log-level", ctx.args.log_level]
    if ctx.args.config:
        argv += ["--config", ctx.args.config]
    return argv


def router_argv(ctx: ServiceContext, plan: UpPlan) -> list[str]:
    argv = [sys.executable, "-m", "buddybot", "router", "--log-level", ctx.args.log_level]
    if ctx.args.config:
        argv += ["--config", ctx.args.config]
    for endpoint in plan.listen:
        argv += ["--listen", endpoint]
    if plan.router_file:
        argv += ["--zenoh-config", plan.router_file]
    return argv


def _announcer(name: str) -> Callable[[str], None]:
    """Where a person looks at the robot (the eye page, the dashboard, Foxglove),
    logged when the service itself says it serves there: a service that could
    not listen has no address printed."""
    def on_line(line: str) -> None:
        address = ports.served_address(name, line)
        if address is not None:
            log.info("%s", address)
    return on_line


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def _busy(listen: list[str], zenoh_file: str | None) -> str | None:
    """The refusal line if any of our router's ports is taken, else None."""
    for endpoint in listen:
        if endpoints.accepting(endpoint):
            nodes, _ = doctor.port_users(endpoints.connect_endpoint(endpoint), zenoh_file,
                                         PROBE_TIMEOUT_S)
            return busy_message(endpoint, nodes)
    return None


def _quick_doctor(ctx: ServiceContext, plan: UpPlan) -> None:
    """The quick doctor's one-line summary (its port check is `_busy`'s job)."""
    opts = doctor.Options(sim=ctx.args.sim, endpoint=plan.connect[0], robot=ctx.robot,
                          zenoh_file=plan.zenoh_file)
    try:
        checks = doctor.quick_checks(ctx.config, None, opts, port=False)
    except Exception as exc:  # a check that breaks must not stop the robot
        log.warning("doctor: could not run the quick checks: %r", exc)
        return
    line = doctor.summary(checks)
    if doctor.exit_code(checks):
        log.warning("%s (`buddybot doctor --quick` for details)", line)
    else:
        log.info("%s", line)


def _start_router(router: Child, plan: UpPlan, out: IO[str], lock: threading.Lock,
                  stop: threading.Event, timeout: float = 15.0) -> int | None:
    """Start our router and wait until *it* listens; an exit status on failure.

    Ready means our router said so (sd_notify READY=1, sent once its listening
    socket is bound), not "something accepts on the port": another program that
    took the port meanwhile must not be joined."""
    router.start(out, lock)
    end = time.monotonic() + timeout
    while not router.ready.wait(0.1):
        if stop.is_set():
            return 0
        if not router.alive():
            assert router.proc is not None
            code = router.proc.returncode
            busy = _busy(plan.listen, plan.zenoh_file)  # someone took the port meanwhile?
            _say(busy or f"buddybot up: the router exited with status {code} before "
                 f"listening on {', '.join(plan.listen)} (its output is above). "
                 "Nothing started.")
            return EXIT_USAGE if code == EXIT_USAGE else EXIT_FAILURE
        if time.monotonic() > end:
            _say(f"buddybot up: the router did not listen on {', '.join(plan.listen)} "
                 f"within {timeout:.0f} s. Nothing started.")
            return EXIT_FAILURE
    return None


def up(ctx: ServiceContext) -> int:
    """Run the whole robot on this machine until Ctrl-C."""
    args = ctx.args
    plan = plan_up(ctx)
    out, lock = sys.stdout, threading.Lock()
    _quick_doctor(ctx, plan)
    if plan.joins:
        reachable = [e for e in plan.connect if not endpoints.over_tcp(e)
                     or endpoints.accepting(e)]
        if not reachable:
            _say(f"buddybot up: no router answers at {', '.join(plan.connect)} "
                 "(--connect joins a running router). Nothing started.")
            return EXIT_FAILURE
    else:
        busy = _busy(plan.listen, plan.zenoh_file)
        if busy:
            _say(busy)
            return EXIT_FAILURE
    taken = ports.first_taken(ports.planned_ports(ctx.config, args,
                                                  [e.name for e in plan.entries]))
    if taken:
        _say(taken)
        return EXIT_USAGE
    router: Child | None = None
    if not plan.joins:
        router = Child("router", router_argv(ctx, plan), notify=True)
    children: list[Child] = []
    where = f"joining the router at {', '.join(plan.connect)}" if router is None \
        else f"starting router on {', '.join(plan.listen)}"
    log.info("%s and %d services: %s", where, len(plan.entries),
             ", ".join(e.name for e in plan.entries))
    if plan.apps:
        log.info("and %d apps: %s", len(plan.apps), ", ".join(a.name for a in plan.apps))
    try:
        if router is not None:
            failed = _start_router(router, plan, out, lock, ctx.stop)
            if failed is not None:
                return failed
        for entry in plan.entries:
            child = Child(entry.name, service_argv(entry.name, ctx, plan.connect,
                                                   plan.service_args.get(entry.name)),
                          on_line=_announcer(entry.name))
            child.start(out, lock)
            children.append(child)
        for app in plan.apps:
            child = Child(app.name, app_argv(app, ctx, plan.connect))
            child.start(out, lock)
            children.append(child)
        monitor = _monitor(ctx, plan, [e.name for e in plan.entries]
                           + [a.name for a in plan.apps])
        try:
            status = _supervise(router, children, ctx.stop, out, lock, monitor,
                                args.status_period, plan)
        finally:
            if monitor is not None:
                monitor.close()
                monitor.session_close()
    finally:
        _stop_all(children)  # services first, so they leave while the router is up
        if router is not None:
            _stop_all([router])
    return status


class _Monitor(StatusMonitor):
    """The status monitor of `up`, owning its probe node."""

    def session_close(self) -> None:
        """Close the probe node (after `close()`, which ends the subscriptions)."""
        self.node.close()


def _monitor(ctx: ServiceContext, plan: UpPlan, expected: list[str]) -> _Monitor | None:
    """A status probe on our own router; None if it cannot be had (status is optional).

    The probe shares `ctx.stop`, so Ctrl-C still interrupts its wait for the
    router (closing it sets `ctx.stop`, which `up` has set by then anyway)."""
    if ctx.args.status_period <= 0:
        return None
    try:
        node = Node("up-status", robot=ctx.robot, connect=plan.connect,
                    zenoh_config_file=plan.zenoh_file, stop_event=ctx.stop, probe=True)
    except ConnectionError as exc:
        log.warning("no status line: %s", exc)
        return None
    except KeyboardInterrupt:  # stopped while waiting for the router
        return None
    return _Monitor(node, expected)


def _supervise(router: Child | None, children: list[Child], stop: threading.Event,
               out: IO[str], lock: threading.Lock, monitor: _Monitor | None, period: float,
               plan: UpPlan) -> int:
    """Restart what dies until `stop`; the exit status of `up`.

    A service that exits with a final status (2) is reported once and left down;
    the others keep running, and the status line counts it as down. The router is
    different: without it nothing works, so if it cannot come back (its port taken
    by another program, or a final status) `up` stops everything.
    """
    everyone = ([router] if router is not None else []) + children
    next_status = time.monotonic() + period
    while not stop.wait(0.2):
        now = time.monotonic()
        if monitor is not None and now >= next_status:
            next_status = now + period
            given_up = {c.name: c.proc.returncode for c in children
                        if c.given_up and c.proc is not None}
            line = monitor.line(sum(c.restarts for c in everyone), given_up)
            with lock:
                out.write(f"[{'status':<14}] {line}\n")
                out.flush()
        for child in everyone:
            if child.proc is None or child.given_up or child.alive():
                continue
            if child.next_start == 0.0:
                code = child.proc.returncode
                delay = child.policy.after_exit(code, now - child.started)
                if delay is None:
                    child.given_up = True
                    if child is router:
                        _say(f"buddybot up: the router exited with status {code} (bad "
                             "Zenoh config?): stopping everything")
                        return EXIT_FAILURE
                    log.error("%s exited with status %s (bad option or config, or a node of "
                              "that name already runs): not restarting it; the others keep "
                              "running", child.name, code)
                    continue
                child.next_start = now + delay
                log.warning("%s exited with status %s; restarting in %.0f s",
                            child.name, code, delay)
            elif now >= child.next_start:
                if child is router:
                    busy = _busy(plan.listen, plan.zenoh_file)
                    if busy:  # another program took our port: never join it
                        _say(busy.replace("Nothing started.", "Stopping everything."))
                        return EXIT_FAILURE
                child.restarts += 1
                child.next_start = 0.0
                log.info("restarting %s (restart %d)", child.name, child.restarts)
                child.start(out, lock)
    return 0


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
