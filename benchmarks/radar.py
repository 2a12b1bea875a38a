"""Radar benchmark: parser throughput, presence latency, bridge CPU. Prints figures.

    .venv/bin/python benchmarks/radar.py [--events 20] [--cpu-seconds 20]

1. Parser throughput on one core: engineering and basic report frames fed
   in 4 KiB chunks; one 4 MB `feed()` of garbage, false headers and frames
   (a parser that rescans its buffer would take minutes); the bridge's whole per-frame path
   (parse, convert to the contract message, encode); the presence rule per
   frame, alone and under a flood of invented sensor ids.
2. Presence latency: a simulated LD2410 on a pty alternates "person at
   1 m" and "nobody"; `radar-bridge` and `radar-presence` run as processes
   on a real router. Latency = time the IN_RANGE sample reaches a
   subscriber minus its `stamp_ns`, which is the arrival time of the near
   frame at the bridge (same host clock).
3. CPU of `radar-bridge` reading 2 simulated sensors at 10 Hz each
   (engineering frames), from /proc via psutil over a window.
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil
import results
from common import best_parse_rate

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import ld2410 as p
from buddybot.radar.convert import report_to_frame
from buddybot.radar.mounting import Mount
from buddybot.radar.presence import PresenceTracker, Reading
from buddybot.radar.sim import PtySensor
from buddybot.radar.sim_scene import NOBODY, Target
from buddybot.radar.world_view import world_script
from buddybot.runtime.node import Node
from buddybot.sim.scenario import load
from buddybot.sim.world import World
from buddybot.tools.testing import Collector, Router, retry_until, run_service


def _frames(engineering: bool, n: int) -> bytes:
    rng = random.Random(1)
    out = bytearray()
    for _ in range(n):
        d = rng.randint(0, 600)
        if engineering:
            r = p.Report(3, d, 50, d + 10, 60, d, engineering=True, max_moving_gate=8,
                         max_still_gate=8, moving_gate_energy=tuple(rng.choices(range(101), k=9)),
                         still_gate_energy=tuple(rng.choices(range(101), k=9)),
                         light_level=80, out_pin=1)
        else:
            r = p.Report(1, d, 50, d, 60, d)
        out += p.encode_report(r)
    return bytes(out)


def bench_parser() -> None:
    n = 50_000
    for name, engineering in (("engineering (45 B)", True), ("basic (23 B)", False)):
        best = best_parse_rate(p.Parser, _frames(engineering, n), n)
        print(f"parser, {name:<20}: {best:>10,.0f} frames/s ({1e6 / best:.2f} us/frame)")
    data = _frames(True, 20_000)
    chunks = [data[i:i + 45] for i in range(0, len(data), 45)]  # one read per frame, as live
    codec = keys.RADAR_FRAMES.codec
    parser = p.Parser()
    t0 = time.perf_counter()
    for c in chunks:
        for r in parser.feed(c):
            frame = report_to_frame(r, 0).frame  # type: ignore[arg-type]
            codec.encode(m.LD2410TargetDataFrameArray(stamp_ns=1, device_id=0, sensors=[frame]))
    dt = time.perf_counter() - t0
    print(f"bridge path per frame (parse+convert+encode, 1 read/frame): "
          f"{20_000 / dt:,.0f} frames/s ({dt / 20_000 * 1e6:.1f} us/frame)")
    tracker = PresenceTracker()
    reading = Reading(1, 150, 150, 0)
    t0 = time.perf_counter()
    for i in range(100_000):
        tracker.update("0/0", reading, i * 0.1, i)
    dt = time.perf_counter() - t0
    print(f"presence rule per frame: {dt / 100_000 * 1e6:.2f} us")
    tracker = PresenceTracker()
    nobody = Reading(0, 0)
    t0 = time.perf_counter()
    for i in range(100_000):
        if i % 100 == 0:
            tracker.update("0/0", reading, i * 0.001, i)
        tracker.update(f"evil/{i}", nobody, i * 0.001, i)
    dt = time.perf_counter() - t0
    print(f"presence rule per frame of an invented sensor (100k ids, table of "
          f"{tracker.rules.max_sensors}): {dt / 100_000 * 1e6:.2f} us, "
          f"{tracker.evicted:,} evicted, real sensor kept: {'0/0' in tracker.known_sensors()}")


def _big_blob(megabytes: float) -> tuple[bytes, int]:
    """Garbage (no header bytes), partial false headers and frames, like the test."""
    rng = random.Random(3)
    frames = [p.encode_report(p.Report(rng.randrange(7), rng.randrange(700), 50, 100, 60, 100))
              for _ in range(200)]
    garbage = bytes(b for b in rng.randbytes(60) if b not in (0xF4, 0xFD)) + b"\xf4\xf3\xf2"
    out = bytearray()
    n = 0
    while len(out) < megabytes * 1e6:
        for frame in frames:
            out += garbage[:rng.randrange(len(garbage))] + frame
            n += 1
    return bytes(out), n


def bench_big_feed() -> None:
    data, n = _big_blob(4.0)
    best = 0.0
    for _ in range(3):
        parser = p.Parser()
        t0 = time.perf_counter()
        got = len(parser.feed(data))
        dt = time.perf_counter() - t0
        assert got == n
        best = max(best, len(data) / dt)
    print(f"parser, one feed of {len(data) / 1e6:.1f} MB (garbage + {n:,} frames): "
          f"{best / 1e6:.1f} MB/s ({len(data) / best:.2f} s)")


class Blinker:
    """Person at 1 m for `near_s`, then nobody for `away_s`, over and over."""

    def __init__(self, near_s: float = 1.0, away_s: float = 1.5) -> None:
        self.near_s, self.away_s = near_s, away_s

    def __call__(self, t: float, rng: random.Random) -> Target:
        if t % (self.near_s + self.away_s) < self.near_s:
            return Target(1, 100, 60, 100, 20, 100)
        return NOBODY


def bench_latency(router: Router, events: int, folder: Path) -> None:
    sensor = PtySensor(Blinker(), link=folder / "ttyLatency").start()
    procs = [run_service("radar-bridge", router.endpoint, "--sensor", sensor.path),
             run_service("radar-presence", router.endpoint, "--absence-hold-s", "0.3")]
    latencies: list[float] = []
    lock = threading.Lock()
    node = Node("bench", connect=[router.endpoint])

    def on_presence(msg: m.PresenceDetection, _key: str) -> None:
        now = time.time_ns()
        if msg.presence_state == m.PresenceState.IN_RANGE:
            with lock:
                latencies.append((now - msg.stamp_ns) / 1e6)

    try:
        node.subscribe(keys.PRESENCE, on_presence, history=False)
        retry_until(lambda: len(latencies) >= events + 1, 60 + events * 5, 0.1,
                    f"{events} IN_RANGE events")
    finally:
        node.close()
        for proc in procs:
            proc.stop()
        sensor.stop()
    values = sorted(latencies[1:])  # the first may predate our subscription
    print(f"presence latency, near frame arrival at the bridge -> IN_RANGE at a subscriber "
          f"(n={len(values)}, entering hold 0 s): median {statistics.median(values):.2f} ms, "
          f"p90 {values[int(0.9 * (len(values) - 1))]:.2f} ms, max {values[-1]:.2f} ms")


def bench_cpu(router: Router, seconds: float, folder: Path) -> None:
    visit = World(load("visit"))
    sensors = [PtySensor(world_script(visit, "LD2410", Mount()), link=folder / f"ttyCpu{i}",
                         seed=i).start() for i in range(2)]
    bridge = run_service("radar-bridge", router.endpoint, "--sensor", sensors[0].path,
                         "--sensor", sensors[1].path)
    presence = run_service("radar-presence", router.endpoint)
    node = Node("bench-cpu", connect=[router.endpoint])
    try:
        frames = Collector(node, keys.RADAR_FRAMES)
        frames.wait_count(40, timeout=60)  # both sensors flowing
        time.sleep(2.0)  # let start-up work settle before measuring (not a synchronisation)
        procs = {"radar-bridge": psutil.Process(bridge.pid),
                 "radar-presence": psutil.Process(presence.pid)}
        before = {k: sum(v.cpu_times()[:2]) for k, v in procs.items()}
        n0 = len(frames.messages)
        t0 = time.monotonic()
        time.sleep(seconds)  # the measurement window itself
        dt = time.monotonic() - t0
        n = len(frames.messages) - n0
        for name, proc in procs.items():
            cpu = (sum(proc.cpu_times()[:2]) - before[name]) / dt * 100
            print(f"CPU of {name} (2 sensors x 10 Hz, {n / dt:.1f} frames/s received): "
                  f"{cpu:.2f} % of one core over {dt:.0f} s")
    finally:
        node.close()
        presence.stop()
        bridge.stop()
        for s in sensors:
            s.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--events", type=int, default=20, help="IN_RANGE events to time")
    parser.add_argument("--cpu-seconds", type=float, default=20.0, help="CPU window")
    args = parser.parse_args()
    print(f"host: {psutil.cpu_count()} cores, Python {sys.version.split()[0]}")
    bench_parser()
    bench_big_feed()
    folder = Path(tempfile.mkdtemp(prefix="buddybot-radar-bench-"))
    router = Router()
    try:
        bench_latency(router, args.events, folder)
        bench_cpu(router, args.cpu_seconds, folder)
    finally:
        router.stop()
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
