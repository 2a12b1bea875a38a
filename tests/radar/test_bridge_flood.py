"""A flooding LD2450 on `socket://`: the bridge publishes fresh reports, not a backlog.

Measured before: 10 MB/s of reports over a stream server made the bridge publish
frames several seconds stale (it read a socket a byte at a time and parsed all of
it). Now it drains what waits in one go and parses only the newest bytes, the
backlog counted as `stale_bytes`.
"""

from __future__ import annotations

import socket
import statistics
import threading
import time
from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import bridge
from buddybot.radar import ld2450 as p2
from buddybot.runtime.node import Node
from buddybot.tools.testing import LOOPBACK, Collector, Process

BATCH = 1000
"""Reports sent in one write; a batch's number b is in its reports' first target:
x = b mod 4000 mm, y = 1000 + b div 4000 mm (unique for 12 million batches)."""
FLOOD_S = 6.0
RATE_BPS = 10_000_000
"""The flood: 10 MB/s, some 400 times what an LD2450 sends."""


def report(n: int) -> bytes:
    return p2.encode_report(p2.Report((p2.Target(n, 1500, 0, 360), None, None)))


def test_a_backlog_keeps_only_its_newest_bytes_and_its_newest_report() -> None:
    normal = report(1) + report(2)  # what a sensor sends between two reads: all kept
    assert bridge.fresh_bytes(normal) == (normal, 0)
    flood = b"".join(report(n) for n in range(1, 1001))
    kept, stale = bridge.fresh_bytes(flood)
    assert len(kept) == bridge.FRESH_BYTES and stale == len(flood) - bridge.FRESH_BYTES
    assert kept == flood[-bridge.FRESH_BYTES:]  # the newest bytes
    frames = [f for f in p2.Parser().feed(kept) if isinstance(f, p2.Report)]
    published, superseded = bridge.newest_reports(list(frames), backlog=True)
    assert len(published) == 1 and superseded == len(frames) - 1
    assert published[0].slots[0] == p2.Target(1000, 1500, 0, 360)  # the very last one
    assert bridge.newest_reports(list(frames), backlog=False) == (list(frames), 0)


class Flood:
    """A stream server that sends LD2450 reports at RATE_BPS (as fast as the socket
    takes them when it is slower), batch b's reports carrying b, and the time each
    batch was sent."""

    def __init__(self) -> None:
        self.server = socket.create_server((LOOPBACK, 0))
        self.url = f"socket://{LOOPBACK}:{self.server.getsockname()[1]}"
        self.sent_at: dict[int, float] = {}
        self.bytes_sent = 0
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.server.settimeout(30)
        conn, _ = self.server.accept()
        with conn:
            batch = 0
            start = time.monotonic()
            while not self._stop.is_set():
                batch += 1
                # The pace (not a synchronisation). Read the clock once: read again for
                # the sleep, a preempted thread got a negative length and died.
                self._stop.wait(max(0.0, start + self.bytes_sent / RATE_BPS - time.monotonic()))
                frame = p2.encode_report(p2.Report((p2.Target(
                    batch % 4000, 1000 + batch // 4000, 0, 360), None, None)))
                try:
                    self.sent_at[batch] = time.monotonic()
                    conn.sendall(frame * BATCH)
                except OSError:
                    return
                self.bytes_sent += len(frame) * BATCH

    def close(self) -> None:
        self._stop.set()
        self.server.close()
        self.thread.join(10)


@pytest.mark.integration
def test_a_flooding_sensor_gets_its_newest_reports_published_not_a_backlog(
        spawn: Callable[..., Process], probe: Node) -> None:
    received: list[tuple[float, int]] = []
    lock = threading.Lock()

    def on_targets(msg: m.RadarTargets, _key: str) -> None:
        if msg.targets:
            with lock:
                first = msg.targets[0]
                received.append((time.monotonic(), round(first.x_m * 1000)
                                 + 4000 * (round(first.y_m * 1000) - 1000)))

    probe.subscribe(keys.RADAR_TARGETS, on_targets, device="0")
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="radar-bridge")
    flood = Flood()
    try:
        spawn("radar-bridge", "--sensor", flood.url)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with lock:
                if received and received[-1][0] - received[0][0] >= FLOOD_S:
                    break
            time.sleep(0.1)  # polling a list the subscriber fills (not a synchronisation)
        counted = diag.wait_for(lambda d: int(d.values.get("stale_bytes", 0)) > 0, 30,
                                "the backlog counted")
    finally:
        flood.close()
    with lock:
        late = [t for t, _ in received if t >= received[-1][0] - FLOOD_S / 2]
        lags = [t - flood.sent_at[b] for t, b in received
                if t >= received[-1][0] - FLOOD_S / 2 and b in flood.sent_at]
    rate = flood.bytes_sent / 1e6 / max(FLOOD_S, 1e-9)
    print(f"flood of ~{rate:.0f} MB/s: {len(received)} reports published, lag of the "
          f"second half median {statistics.median(lags) * 1000:.0f} ms, max "
          f"{max(lags) * 1000:.0f} ms; stale bytes {counted.values['stale_bytes']}")
    assert late and lags, "no report published during the flood"
    assert statistics.median(lags) < 1.0, f"stale: {statistics.median(lags):.2f} s behind"
