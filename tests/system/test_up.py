"""`buddybot up --sim`: the whole robot from one command, stopped by one Ctrl-C.

Also the supervisor's faults: killed with SIGKILL it leaves no child behind; a
second `up` on a busy port refuses instead of joining the running robot; a child
that exits with status 2 is not restarted. The restart rule itself is pure and
tested without processes.
"""

from __future__ import annotations

import contextlib
import signal
import socket
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from buddybot.runtime.registry import available_services
from buddybot.runtime.supervised import SUPERVISOR_ENV
from buddybot.supervisor.launch import RestartPolicy, busy_message, child_env
from buddybot.tools.testing import (
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
    run_service,
    stop_and_report,
)


@pytest.mark.integration
def test_up_sim_runs_restarts_a_crashed_service_and_stops_cleanly(tmp_path: Path) -> None:
    port = free_port()
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen", f"tcp/127.0.0.1:{port}",
                               "--eye-port", str(free_port()),
                               "--dashboard-port", str(free_port()),
                               "--status-period", "1"), "up", tmp_path)
    try:
        expected = len([e for e in available_services() if not e.on_request])
        up.wait_for_output(f"nodes {expected}/{expected}", 120)
        # Every service is its own process, and the router one more.
        children = psutil.Process(up.pid).children(recursive=True)
        assert len(children) >= expected + 1
        # The simulated visitor and face reach the status line.
        retry_until(lambda: "presence IN_RANGE" in up.output(), 60, 0.5, "presence in status")
        retry_until(lambda: " | face 0." in up.output() or " | face 1." in up.output(), 60, 0.5,
                    "face distance in status")

        # A service that crashes is restarted and reported.
        victim = next(c for c in children if "controller" in " ".join(c.cmdline()))
        victim.kill()
        up.wait_for_output("controller exited with status", 30)
        up.wait_for_output("restarting controller", 30)

        def back() -> bool:
            last = [x for x in up.output().splitlines() if x.startswith("[status")][-1]
            return f"nodes {expected}/{expected} |" in last and "restarts 1" in last

        retry_until(back, 60, 0.5, "controller back and the restart reported")

        # One Ctrl-C stops everything within a few seconds, nothing left behind.
        everyone = psutil.Process(up.pid).children(recursive=True)
        up.proc.send_signal(signal.SIGINT)
        assert up.proc.wait(30) == 0
        _gone, alive = psutil.wait_procs(everyone, timeout=10)
        assert not alive, [p.cmdline() for p in alive]
        assert "all stopped" in up.output()
    finally:
        up.stop()


# --- the restart rule ------------------------------------------------------------------


def test_backoff_doubles_to_thirty_seconds() -> None:
    policy = RestartPolicy()
    delays = [policy.after_exit(1, ran_s=0.5) for _ in range(8)]
    assert delays == [1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0, 30.0]


def test_a_stable_run_starts_the_series_again() -> None:
    policy = RestartPolicy()
    for _ in range(4):
        policy.after_exit(1, ran_s=2.0)
    assert policy.after_exit(-9, ran_s=29.0) == 16.0  # not stable yet
    assert policy.after_exit(1, ran_s=30.0) == 1.0  # ran 30 s: healthy, start over
    assert policy.after_exit(1, ran_s=1.0) == 2.0


def test_status_two_is_never_restarted() -> None:
    """Bad option or config, or a node of that name already running: final."""
    policy = RestartPolicy()
    assert policy.after_exit(2, ran_s=0.1) is None
    assert policy.after_exit(2, ran_s=3600.0) is None
    assert policy.after_exit(1, ran_s=0.1) == 1.0  # and it did not advance the backoff
    assert policy.after_exit(None, ran_s=0.1) == 2.0


def test_busy_port_message_names_the_port_and_the_nodes() -> None:
    line = busy_message("tcp/127.0.0.1:7447", ["buddy/camera", "buddy/controller"])
    assert "tcp/127.0.0.1:7447 is already in use" in line
    assert "live nodes: buddy/camera, buddy/controller" in line
    assert "Nothing started" in line and "\n" not in line
    assert "no live BuddyBot nodes" in busy_message("tcp/127.0.0.1:7447", [])
    assert "does not answer as a Zenoh router" in busy_message("tcp/127.0.0.1:7447", None)


def test_children_do_not_inherit_systemd_notification() -> None:
    """Under systemd, `up` is the unit's main process: a child must not answer for it."""
    env = child_env({"NOTIFY_SOCKET": "/run/systemd/notify", "WATCHDOG_USEC": "10000000",
                     "WATCHDOG_PID": "1", "PATH": "/usr/bin"}, supervisor_pid=4242)
    assert env == {"PATH": "/usr/bin", "PYTHONUNBUFFERED": "1", SUPERVISOR_ENV: "4242"}


# --- supervisor faults, real processes --------------------------------------------------


@contextlib.contextmanager
def reaped(procs: list[psutil.Process]) -> Iterator[None]:
    """Whatever happens in the test, every process in `procs` is killed afterwards
    (children of a SIGKILLed `up` are in their own sessions: killpg misses them).
    psutil remembers each one's start time, so a reused pid is never hit."""
    try:
        yield
    finally:
        for proc in procs:
            with contextlib.suppress(psutil.Error):
                proc.kill()


def started_by_up(port: int) -> list[psutil.Process]:
    """Processes of an `up` on `port`: its router and the services connecting to it."""
    found = []
    for proc in psutil.process_iter(["cmdline"]):
        line = " ".join(proc.info["cmdline"] or [])
        if "buddybot" in line and f"127.0.0.1:{port}" in line and " up " not in f"{line} ":
            found.append(proc)
    return found


def run_up_to_exit(tmp_path: Path, *args: str, timeout: float = 60.0) -> tuple[int | None, str]:
    """Run `up --sim --no-browser ARGS` expecting it to exit by itself: (status, output).

    If it does not (the refusal broken), it and everything it started are killed.
    """
    up = Process(buddybot_argv("up", "--sim", "--no-browser", *args), "up-refused", tmp_path)
    left: list[psutil.Process] = []
    with reaped(left):
        try:
            with contextlib.suppress(TimeoutError):
                retry_until(lambda: not up.alive(), timeout, 0.1, "up exiting by itself")
            if up.alive():
                left.extend(psutil.Process(up.pid).children(recursive=True))
        finally:
            up.stop()
    return up.proc.returncode if not left else None, up.output()


@pytest.mark.integration
def test_children_die_with_a_killed_up(tmp_path: Path) -> None:
    """kill -9 of `up`: the router and every service are gone within seconds."""
    port = free_port()
    only = ["radar-bridge", "radar-presence", "controller"]
    argv = ["up", "--sim", "--no-browser", "--listen", f"tcp/127.0.0.1:{port}",
            "--status-period", "1"]
    for name in only:
        argv += ["--only", name]
    up = Process(buddybot_argv(*argv), "up", tmp_path)
    children: list[psutil.Process] = []
    with reaped(children):
        try:
            up.wait_for_output(f"nodes {len(only)}/{len(only)}", 120)
            children.extend(psutil.Process(up.pid).children(recursive=True))
            assert len(children) == len(only) + 1  # and the router
            up.kill(signal.SIGKILL)
            _gone, alive = psutil.wait_procs(children, timeout=15)
            assert not alive, f"orphans of a killed up: {[p.cmdline() for p in alive]}"
            # Nothing left that would make the next `up` join a dead robot's bus.
            with socket.socket() as probe:
                assert probe.connect_ex(("127.0.0.1", port)) != 0
        finally:
            up.stop()


@pytest.mark.integration
def test_child_whose_supervisor_is_already_gone_does_not_start(tmp_path: Path) -> None:
    """The window between exec and PR_SET_PDEATHSIG: a child that finds another parent
    than the `up` named in its environment exits at once instead of running orphaned."""
    port = free_port()
    child = run_service("radar-presence", f"tcp/127.0.0.1:{port}", log_dir=tmp_path,
                        env={SUPERVISOR_ENV: "1"})  # our parent is pytest, not pid 1
    try:
        assert child.proc.wait(60) == 1
        assert "the `buddybot up` that started it is gone; not starting" in child.output()
        assert "waiting for the Zenoh router" not in child.output()
    finally:
        child.stop()


@pytest.mark.integration
def test_second_up_on_a_busy_port_refuses_and_starts_nothing(tmp_path: Path) -> None:
    router = Router(log_dir=tmp_path)
    procs: list[Process] = [router]
    try:
        procs.append(run_service("radar-presence", router.endpoint, log_dir=tmp_path))
        procs[-1].wait_for_output("node radar-presence up", 60)
        before = {p.pid for p in started_by_up(router.port)}
        status, out = run_up_to_exit(tmp_path, "--listen", router.endpoint)
        assert status == 1, out
        lines = [x for x in out.splitlines() if "already in use" in x]
        assert len(lines) == 1, out
        assert f"{router.endpoint} is already in use" in lines[0]
        assert "buddy/radar-presence" in lines[0]
        assert "starting router" not in out
        after = {p.pid for p in started_by_up(router.port)}
        assert after == before, "the refused up started something"
    finally:
        stop_and_report(procs)


@pytest.mark.integration
def test_up_refuses_a_port_held_by_something_else(tmp_path: Path) -> None:
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(8)
        port = holder.getsockname()[1]
        status, out = run_up_to_exit(tmp_path, "--listen", f"tcp/127.0.0.1:{port}")
    assert status == 1, out
    assert f"tcp/127.0.0.1:{port} is already in use" in out
    assert "does not answer as a Zenoh router" in out
    assert "starting router" not in out


@pytest.fixture
def bad_eyes_config(tmp_path: Path) -> Path:
    """A config only the eyes driver refuses (exit status 2): its pupil curve goes backwards."""
    path = tmp_path / "robot.toml"
    path.write_text("[eyes]\npupil_curve = [[1.0, 50.0], [0.5, 60.0]]\n")
    return path


@pytest.mark.integration
def test_child_exiting_with_status_two_is_reported_once_and_not_restarted(
    tmp_path: Path, bad_eyes_config: Path
) -> None:
    port = free_port()
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--config", str(bad_eyes_config),
                               "--listen", f"tcp/127.0.0.1:{port}", "--status-period", "1",
                               "--only", "eyes", "--only", "radar-presence"), "up", tmp_path)
    try:
        up.wait_for_output("eyes exited with status 2", 120)
        given_up_at = up.output().count("[status")

        # Long enough for restarts with backoff (1 s, then 2 s) to have restarted it twice.
        retry_until(lambda: up.output().count("[status") >= given_up_at + 6, 60, 0.2,
                    "six more status lines")
        out = up.output()
        assert out.count("eyes exited with status") == 1, out
        assert "not restarting it" in out
        assert "restarting eyes" not in out
        # The rest keep running.
        last = [x for x in out.splitlines() if x.startswith("[status")][-1]
        assert "nodes 1/2 (down: eyes)" in last
        presence = [c for c in psutil.Process(up.pid).children(recursive=True)
                    if "radar-presence" in " ".join(c.cmdline())]
        assert len(presence) == 1 and presence[0].is_running()
    finally:
        up.stop()
