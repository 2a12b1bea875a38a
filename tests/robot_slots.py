"""Test runs share the machine: at most `SLOTS` robots and `HEAVY` tests with
processes or a browser at once, however many runs of the suite are going.

A test marked `robot` runs the robot's perception and behaviour in real time
(a camera at 15 fps, face detection, a dozen processes: about a third of a core)
and judges what it decided. Under pytest-xdist they go to `SLOTS` groups, so
one run never has more than `SLOTS` robots going, and no worker waits; and
each group holds its slot's lock file (in the system's temporary folder) while
a test of it runs, so a second run of the suite on the machine takes turns
with this one instead of starving both robots of the CPU their timing needs.

Every other test with processes or a browser (marked `integration` or
`browser`) holds one of `HEAVY` machine-wide slots while it runs: as many as
one run has workers, so a run alone never waits, and two runs together load
the machine as one does (their pure tests still run beside).
"""

from __future__ import annotations

import fcntl
import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

SLOTS = 2
"""Robots at once on the machine: about one core of a two-core machine."""
HEAVY = 3 * (os.cpu_count() or 1)
"""Heavy tests at once on the machine: scripts/test.sh's workers of one run."""
WAIT_S = 3600.0
"""How long a test waits for a heavy slot before it fails saying so."""
FOLDER = Path(tempfile.gettempdir()) / "buddybot-robot-slots"


def assign(items: list[pytest.Item]) -> None:
    """Put the `robot` tests into the slots' xdist groups, in turn."""
    robots = [i for i in items if i.get_closest_marker("robot") is not None]
    for n, item in enumerate(robots):
        item.add_marker(pytest.mark.xdist_group(group(n % SLOTS)))


def group(slot: int) -> str:
    return f"robot-{slot}"


def heavy(item: pytest.Item) -> bool:
    return any(item.get_closest_marker(m) is not None for m in ("integration", "browser"))


def slot_of(item: pytest.Item) -> int | None:
    """The slot a `robot` test was put in (None: not a robot test)."""
    for mark in item.iter_markers("xdist_group"):
        for slot in range(SLOTS):
            if mark.args and mark.args[0] == group(slot):
                return slot
    return None


@contextmanager
def held(slot: int) -> Iterator[None]:
    """Hold the slot's lock file: wait (the kernel wakes us) while another run's
    robot test holds it."""
    FOLDER.mkdir(exist_ok=True)
    fd = os.open(FOLDER / f"{slot}.lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


@contextmanager
def any_heavy(wait_s: float = WAIT_S) -> Iterator[None]:
    """Hold one of the `HEAVY` slots, the first found free; poll (every 0.1 s)
    until one is, for at most `wait_s`."""
    FOLDER.mkdir(exist_ok=True)
    end = time.monotonic() + wait_s
    while True:
        for n in range(HEAVY):
            fd = os.open(FOLDER / f"heavy-{n}.lock", os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                continue
            try:
                yield
            finally:
                os.close(fd)
            return
        if time.monotonic() > end:
            raise TimeoutError(f"no heavy-test slot free in {FOLDER} for {wait_s:g} s")
        time.sleep(0.1)  # a poll with a deadline: flock cannot wait for any of several
