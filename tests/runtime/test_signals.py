"""SIGTERM always stops a node process, whatever its main thread is doing.

A signal handler runs in the main thread between two bytecodes. The old one
called `stop.set()` itself, which takes the event's lock: if the main thread
held that lock at that moment (inside `stop.wait()`), the process hung for
good. A service killed by `up`'s death signal was found hung this way.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

pytestmark = pytest.mark.integration  # each case signals a child process

# The main thread takes the stop event's lock all the time, as `spin()` does.
BUSY_WAITER = """
import threading, sys
from buddybot.runtime.node import install_signal_handlers
stop = threading.Event()
install_signal_handlers(stop)
print("READY", flush=True)
while not stop.wait(0):
    pass
print("STOPPED", flush=True)
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_a_main_thread_that_waits_on_the_stop_event(signum: int) -> None:
    for _ in range(5):
        proc = subprocess.Popen([sys.executable, "-c", BUSY_WAITER], stdout=subprocess.PIPE,
                                text=True)
        try:
            assert proc.stdout is not None
            assert proc.stdout.readline().strip() == "READY"
            for _ in range(3):  # several, as a dying supervisor and a user may both send one
                proc.send_signal(signum)
            out, _ = proc.communicate(timeout=20)
            assert "STOPPED" in out and proc.returncode == 0
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
