"""`free_port`: loopback ports that no other process of the machine is handed too."""

from __future__ import annotations

import fcntl
import os
import socket
from pathlib import Path

import pytest

from buddybot.tools import testing


def test_ports_are_distinct_bindable_and_below_the_ephemeral_range() -> None:
    low, high = testing._port_range()
    ports = [testing.free_port() for _ in range(50)]
    assert len(set(ports)) == 50
    assert all(low <= p <= high for p in ports)
    with socket.socket() as sock:
        sock.bind((testing.LOOPBACK, ports[-1]))  # really free


def test_a_port_another_process_holds_is_never_handed_out(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Another holder of the lock file (here: a second descriptor, as another
    process would hold it) keeps its port; the next one is chosen instead."""
    taken, other = testing.free_port(), testing.free_port()  # free, and ours for now
    for port in (taken, other):  # let them go, then hold `taken` as another process would
        os.close(testing._held_ports.pop(port))
    held = os.open(testing.PORTS_DIR / str(taken), os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        choices = iter([taken, taken, other])
        monkeypatch.setattr(testing._random, "randint", lambda a, b: next(choices))
        assert testing.free_port() == other
    finally:
        os.close(held)


def test_the_range_ends_below_the_kernels_ephemeral_ports() -> None:
    low, high = testing._port_range()
    first = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    assert low == 10_000 and high == first - 1
