"""`buddybot hz KEY`: the publishing rate of KEY (like `ros2 topic hz`)."""

from __future__ import annotations

import argparse
import itertools
import statistics
import threading
import time
from collections import deque

from buddybot.core import keys, tools
from buddybot.core.rates import span_hz
from buddybot.core.service import ServiceContext

HELP = "print the publishing rate of KEY"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key")
    parser.add_argument("--window", type=int, default=100, help="samples in the window")
    parser.add_argument("--duration", type=float, default=None,
                        help="exit after this many seconds")


def rate_report(stamps: list[float]) -> str | None:
    """ros2-style rate line from arrival times (seconds), or None if < 2."""
    if len(stamps) < 2:
        return None
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    rate = span_hz(stamps)
    std = statistics.pstdev(gaps)
    return (f"average rate: {rate:.3f} Hz\n\tmin: {min(gaps):.4f}s max: {max(gaps):.4f}s "
            f"std dev: {std:.5f}s window: {len(stamps)}")


def main(ctx: ServiceContext) -> int:
    """Print the publishing rate of KEY every second over a sliding window."""
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    stamps: deque[float] = deque(maxlen=args.window)
    lock = threading.Lock()

    def on_sample(_key: str, _payload: bytes, _encoding: str) -> None:
        with lock:
            stamps.append(time.monotonic())

    printed = 0
    with tools.probe(ctx) as node:
        node.subscribe_raw(key, on_sample)
        end = tools.deadline(args.duration)
        while not ctx.stop.wait(1.0) and time.monotonic() < end:
            with lock:
                report = rate_report(list(stamps))
            print(report or "no new messages", flush=True)
            printed += report is not None
    return 0 if printed or not args.duration else 1
