#!/usr/bin/env python3
"""Recording benchmark: CPU of `buddybot bag record`, and replay timing. Prints figures.

    .venv/bin/python benchmarks/bag.py [--seconds 60]

1. CPU of the recorder: `buddybot up --sim --no-browser` runs the whole
   simulated robot on a free loopback port; `buddybot bag record` records
   everything but raw images (the default) for `--seconds`. Its CPU is
   read from /proc via psutil between 5 s after its start (imports and
   discovery done) and the end of the window. Target: under 3 % of a core.
2. Replay timing: the recording just made is played back on the same
   robot's router (moved to robot id `bench`); the player reports, for
   every message, how late it left against its schedule (log time relative
   to the first message), and a probe subscribed to the replay times every
   sample's arrival: the spread of (arrival - log time) around its median
   is the timing error a subscriber sees. Target: p95 under 5 ms.

Run it when the machine is quiet: both figures are about scheduling.
"""

from __future__ import annotations

import argparse
import collections
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil
import results
from common import percentile

from buddybot.runtime.node import Node
from buddybot.tools import bag
from buddybot.tools.testing import Process, buddybot_argv, free_port, retry_until, wait_port

ROBOT_NODES = ("radar-bridge", "radar-presence", "camera", "face-detector", "controller",
               "eyes", "audio", "audio-player")
WARMUP_S = 5.0


def wait_robot(endpoint: str) -> None:
    node = Node("bench-probe", connect=[endpoint], probe=True)
    try:
        retry_until(lambda: all(f"buddy/{n}" in node.node_instances(all_robots=True)
                                for n in ROBOT_NODES), 120, 0.5, "the simulated robot up")
    finally:
        node.close()


def record_cpu(endpoint: str, out: Path, seconds: float, log_dir: Path) -> tuple[float, str]:
    """% of one core the recorder used over the window, and its summary line."""
    recorder = Process(buddybot_argv("bag", "record", "-o", str(out), "--duration",
                                     str(seconds + WARMUP_S), "--connect", endpoint),
                       "bag-record", log_dir)
    proc = psutil.Process(recorder.pid)
    time.sleep(WARMUP_S)  # the measured window starts once it runs steadily
    before, t0 = proc.cpu_times(), time.monotonic()
    time.sleep(seconds - 0.5)
    after, t1 = proc.cpu_times(), time.monotonic()
    recorder.proc.wait(60)
    recorder.stop()
    used = (after.user + after.system) - (before.user + before.system)
    lines = [ln for ln in recorder.output().splitlines() if ln.startswith("recorded ")]
    return 100.0 * used / (t1 - t0), lines[-1] if lines else recorder.output()[-500:]


def replay_timing(endpoint: str, path: Path) -> tuple[float, float, str, list[float]]:
    """The player's own lateness figures, and the timing error a subscriber sees."""
    arrivals: dict[str, list[int]] = collections.defaultdict(list)
    probe = Node("bench-replay-probe", connect=[endpoint], probe=True)

    def on_sample(key: str, _payload: bytes, _encoding: str) -> None:
        arrivals[key].append(time.monotonic_ns())

    probe.subscribe_raw("buddybot/bench/**", on_sample)
    try:
        result = subprocess.run(buddybot_argv("bag", "play", str(path), "--robot", "bench",
                                              "--connect", endpoint),
                                capture_output=True, text=True, timeout=600)
        time.sleep(0.5)  # the last samples on their way
    finally:
        probe.close()
    line = result.stderr.strip().splitlines()[-1]
    found = re.search(r"p50 ([\d.]+) ms, p95 ([\d.]+) ms", line)
    if result.returncode != 0 or found is None:
        raise SystemExit(f"bag play failed ({result.returncode}): {result.stderr[-2000:]}")
    return float(found[1]), float(found[2]), line, arrival_errors(path, arrivals)


def arrival_errors(path: Path, arrivals: dict[str, list[int]]) -> list[float]:
    """|timing error| in ms of every replayed message as a subscriber received it.

    The i-th sample received on a key is the i-th recorded on it (keys carry
    the replay's robot id `bench`). Its error is its arrival relative to the
    first arrival, minus its log time relative to the first log time; the
    median error (the constant delivery delay) is taken off, so what is left
    is how far the replay's timing strays from the recording's.
    """
    recorded: dict[str, list[int]] = collections.defaultdict(list)
    for item in bag.open_recording(path).messages():
        recorded[bag.with_robot(item.key, "bench")].append(item.log_time_ns)
    pairs = [(a, r) for key, times in recorded.items()
             for a, r in zip(arrivals.get(key, []), times, strict=False)]
    if not pairs:
        raise SystemExit("the probe received nothing of the replay")
    missing = sum(len(t) for t in recorded.values()) - len(pairs)
    if missing:
        print(f"probe: {missing} replayed messages not received", file=sys.stderr)
    a0 = min(a for a, _ in pairs)
    r0 = min(r for _, r in pairs)
    errors = [((a - a0) - (r - r0)) / 1e6 for a, r in pairs]
    centre = statistics.median(errors)
    return [abs(e - centre) for e in errors]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="recording length")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="buddybot-bench-bag-"))
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen", endpoint,
                               "--eye-port", str(free_port()), "--status-period", "0"),
                 "up", folder)
    try:
        wait_port(port, 60)
        wait_robot(endpoint)
        out = folder / "robot.mcap"
        cpu, summary = record_cpu(endpoint, out, args.seconds, folder)
        info = bag.read_info(out)
        print(f"recorder: {summary}")
        print(f"recorder CPU: {cpu:.2f} % of one core over {args.seconds:g} s "
              f"({info.messages / info.duration_s:.0f} messages/s, "
              f"{info.size / info.duration_s / 1e3:.1f} kB/s on disk; target < 3 %)")
        p50, p95, line, errors = replay_timing(endpoint, out)
        print(f"player: {line}")
        print(f"replay lateness vs schedule (the player's own clock): p50 {p50:.2f} ms, "
              f"p95 {p95:.2f} ms")
        print(f"replay timing error seen by a subscriber: p50 {percentile(errors, 0.5):.2f} ms,"
              f" p95 {percentile(errors, 0.95):.2f} ms, max {max(errors):.2f} ms, "
              f"n={len(errors)} (target p95 < 5 ms)")
    finally:
        up.stop(30)
    print(f"logs: {folder}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
