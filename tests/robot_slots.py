"""Whole-robot tests share the machine: at most `SLOTS` robots at once, whatever runs.

A test marked `robot` runs the robot's perception and behaviour in real time
(a camera at 30 fps, face detection, a dozen processes: about half a core)
and judges what it decided. Under pytest-xdist they go to `SLOTS` groups, so
one run never has more than `SLOTS` robots going, and no worker waits; and
each group holds its slot's lock file (in the system's temporary folder) while
a test of it runs, so a second run of the suite on the machine takes turns
with this one instead of starving both robots of the CPU their timing needs.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

SLOTS = 2
"""Robots at once on the machine: about one core of a two-core machine."""
FOLDER = Path(tempfile.gettempdir()) / "buddybot-robot-slots"


def assign(items: list[pytest.Item]) -> None:
    """Put the `robot` tests into the slots' xdist groups, in turn."""
    robots = [i for i in items if i.get_closest_marker("robot") is not None]
    for n, item in enumerate(robots):
        item.add_marker(pytest.mark.xdist_group(group(n % SLOTS)))


def group(slot: int) -> str:
    return f"robot-{slot}"


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
