#!/usr/bin/env python3
"""Hostile recordings: time and peak memory to refuse a decompression bomb. Prints figures.

    .venv/bin/python benchmarks/bag_limits.py [--gib 1]

A 34 kB MCAP whose one zstd chunk holds a `--gib` GiB message (built piece
by piece, never in memory) is given to `buddybot bag play` and `bag
recover`; each runs under a fresh parent that reads its peak RSS
(RUSAGE_CHILDREN) and its wall time. Target: refused in under 2 s with
the memory of an idle process (under 100 MB); the unbounded reader took
2.1 GB and 18 s.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import results

from buddybot.tools.testing import buddybot_argv
from tests.tools.mcap_bomb import write_bomb

_MEASURE = ("import resource, subprocess, sys, time\n"
            "t = time.monotonic()\n"
            "r = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
            "sys.stderr.write(r.stderr)\n"
            "print(r.returncode, time.monotonic() - t,\n"
            "      resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")


def measure(argv: list[str]) -> tuple[int, float, int, str]:
    """(exit status, seconds, peak RSS in kB, last stderr line) of `argv`, run
    under a fresh parent so the peak is this command's alone."""
    outer = subprocess.run([sys.executable, "-c", _MEASURE, *argv], capture_output=True,
                           text=True, timeout=600)
    status, seconds, peak = outer.stdout.split()
    lines = outer.stderr.strip().splitlines() or [""]
    return int(status), float(seconds), int(peak), lines[-1]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gib", type=float, default=1.0, help="the message's size in GiB")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        bomb = Path(folder) / "bomb.mcap"
        size = write_bomb(bomb, int(args.gib * (1 << 30)))
        print(f"file: {size} bytes holding a {args.gib:g} GiB message")
        for verb in (["play", str(bomb)], ["recover", str(bomb), "-o", f"{folder}/out.mcap"]):
            status, seconds, peak_kb, line = measure(buddybot_argv("bag", *verb))
            print(f"bag {verb[0]}: exit {status}, {seconds:.2f} s, peak RSS "
                  f"{peak_kb / 1024:.0f} MB: {line}")
    return 0


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
