"""LD2450 benchmark: parser throughput, and frame -> `radar/{device}/targets`. Prints figures.

    .venv/bin/python benchmarks/ld2450.py [--frames 200]

1. Parser throughput on one core: 30-byte report frames with three targets
   fed in 4 KiB chunks, and one frame per read (as live) through the
   bridge's whole per-frame path: parse, place in the camera's frame,
   build `RadarTargets`, encode.
2. Frame -> bus: a simulated LD2450 on a pty, `radar-bridge` as a process
   on a real router, a subscriber on `radar/0/targets`. Each frame carries
   its sequence number in a target's y; the latency of a frame is the time
   its message reaches the subscriber minus the time the simulator wrote
   it to the pty (same host clock): the serial read, the parser, the
   conversion and Zenoh, all included. Target: median <= 2 ms.
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
from buddybot.radar import ld2450 as p
from buddybot.radar.convert import report_to_targets
from buddybot.radar.sim import PtySensor
from buddybot.radar.sim_scene import Person, Scene
from buddybot.runtime.node import Node
from buddybot.tools.testing import Router, retry_until, run_service


def _frames(n: int) -> list[bytes]:
    rng = random.Random(1)
    return [p.encode_report(p.Report(tuple(
        p.Target(rng.randint(-4000, 4000), rng.randint(1, 8000), rng.randint(-200, 200), 320)
        for _ in range(p.SLOTS)))) for _ in range(n)]


def bench_parser() -> None:
    n = 100_000
    frames = _frames(n)
    best = best_parse_rate(p.Parser, b"".join(frames), n)
    print(f"LD2450 parser, 4 KiB chunks: {best:>10,.0f} frames/s ({1e6 / best:.2f} us/frame)")
    codec = keys.RADAR_TARGETS.codec
    parser = p.Parser()
    live = frames[:20_000]
    t0 = time.perf_counter()
    for chunk in live:
        for r in parser.feed(chunk):
            assert isinstance(r, p.Report)
            codec.encode(report_to_targets(r, 0, 0, 1).message)
    dt = time.perf_counter() - t0
    print(f"LD2450 bridge path, one 30 B read per frame (parse, place, message, encode): "
          f"{len(live) / dt:,.0f} frames/s ({dt / len(live) * 1e6:.1f} us/frame)")


class Numbered:
    """A scenario whose person's y is the frame's sequence number (mm, 1..7999);
    remembers when each number was handed to the simulator (just before it
    writes the frame to the pty)."""

    def __init__(self) -> None:
        self.seq = 0
        self.sent: dict[int, int] = {}

    def __call__(self, t: float, rng: random.Random) -> Scene:
        self.seq = self.seq % 7999 + 1
        self.sent[self.seq] = time.time_ns()
        return Scene((Person(-500, self.seq),))


def bench_latency(router: Router, frames: int, folder: Path) -> None:
    scenario = Numbered()
    sensor = PtySensor(scenario, link=folder / "ttyLD2450", model="LD2450").start()
    proc = run_service("radar-bridge", router.endpoint, "--sensor", sensor.path)
    latencies: list[float] = []
    lock = threading.Lock()
    node = Node("bench-ld2450", connect=[router.endpoint])

    def on_targets(msg: m.RadarTargets, _key: str) -> None:
        now = time.time_ns()
        if msg.targets:
            sent = scenario.sent.get(round(msg.targets[0].y_m * 1000))
            if sent is not None:
                with lock:
                    latencies.append((now - sent) / 1e6)

    try:
        node.subscribe(keys.RADAR_TARGETS, on_targets, device="0")
        retry_until(lambda: len(latencies) >= frames + 10, 60 + frames * 0.2, 0.1,
                    f"{frames} target messages")
    finally:
        node.close()
        proc.stop()
        sensor.stop()
    values = sorted(latencies[10:])  # the first ones include the bridge's start-up
    print(f"LD2450 frame written to the pty -> radar/0/targets at a subscriber "
          f"(n={len(values)}): median {statistics.median(values):.2f} ms, "
          f"p90 {values[int(0.9 * (len(values) - 1))]:.2f} ms, max {values[-1]:.2f} ms "
          f"(target: median <= 2 ms)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=200, help="frames to time on the bus")
    args = parser.parse_args()
    print(f"host: {psutil.cpu_count()} cores, Python {sys.version.split()[0]}")
    bench_parser()
    folder = Path(tempfile.mkdtemp(prefix="buddybot-ld2450-bench-"))
    router = Router()
    try:
        bench_latency(router, args.frames, folder)
    finally:
        router.stop()
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
