#!/usr/bin/env python3
"""Recording benchmark: CPU of `buddybot bag record`, and replay timing. Prints figures.

    .venv/bin/python benchmarks/bag.py [--seconds 60]

1. CPU of the recorder: `buddybot up --sim --no-browser` runs the whole
   simulated robot on a free loopback port; `buddybot bag record` records
   everything but raw images (the default) for `--seconds`. Its CPU is
   read from /proc via psutil between 5 s after its start (imports and
   discovery done) and the end of the window. Target: under 3 % of a core.
2. Replay timing: the recording just made is played back on the same
   robot's router; the player reports, for every message, how late it left
   against its schedule (log time relative to the first message).
   Target: p95 under 5 ms.

Run it when the machine is quiet: both figures are about scheduling.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

from buddybot.core import bag
from buddybot.core.node import Node
from buddybot.core.testing import Process, buddybot_argv, free_port, retry_until, wait_port

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


def replay_timing(endpoint: str, path: Path) -> tuple[float, float, str]:
    result = subprocess.run(buddybot_argv("bag", "play", str(path), "--robot", "bench",
                                          "--connect", endpoint),
                            capture_output=True, text=True, timeout=600)
    line = result.stderr.strip().splitlines()[-1]
    found = re.search(r"p50 ([\d.]+) ms, p95 ([\d.]+) ms", line)
    if result.returncode != 0 or found is None:
        raise SystemExit(f"bag play failed ({result.returncode}): {result.stderr[-2000:]}")
    return float(found[1]), float(found[2]), line


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
        p50, p95, line = replay_timing(endpoint, out)
        print(f"player: {line}")
        print(f"replay lateness vs schedule: p50 {p50:.2f} ms, p95 {p95:.2f} ms "
              "(target p95 < 5 ms)")
    finally:
        up.stop(30)
    print(f"logs: {folder}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
