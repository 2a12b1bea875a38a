"""`buddybot up --sim`: the whole robot from one command, stopped by one Ctrl-C."""

from __future__ import annotations

import signal
from pathlib import Path

import psutil

from buddybot.core.registry import available_services
from buddybot.core.testing import Process, buddybot_argv, free_port, retry_until


def test_up_sim_runs_restarts_a_crashed_service_and_stops_cleanly(tmp_path: Path) -> None:
    port = free_port()
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen", f"tcp/127.0.0.1:{port}",
                               "--status-period", "1"), "up", tmp_path)
    try:
        expected = len(available_services())
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
