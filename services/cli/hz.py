"""`buddybot hz KEY`: the publishing rate of KEY (like `ros2 topic hz`)."""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import sys
import threading
import time
from collections import deque
from typing import Any

from buddybot.contract import keys
from buddybot.runtime import options
from buddybot.runtime.rates import span_hz
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.session import CONNECT_TIMEOUT_S
from buddybot.tools import probing

HELP = "print the publishing rate of KEY"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_key_argument(parser)
    parser.add_argument("--window", type=int, default=100, help="samples in the window")
    parser.add_argument("--duration", type=float, default=None,
                        help="exit after this many seconds")
    options.add_timeout_argument(parser, None, "exit 1 if nothing arrived within S")
    options.add_json_argument(parser,
                              "print one JSON document at exit instead of a line per second")


def rate_stats(stamps: list[float]) -> dict[str, Any] | None:
    """Rate, gaps and window from arrival times (seconds), or None if < 2."""
    if len(stamps) < 2:
        return None
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    return {"rate_hz": span_hz(stamps), "min_s": min(gaps), "max_s": max(gaps),
            "std_s": statistics.pstdev(gaps), "window": len(stamps)}


def rate_report(stamps: list[float]) -> str | None:
    """ros2-style rate line from arrival times (seconds), or None if < 2."""
    stats = rate_stats(stamps)
    if stats is None:
        return None
    return (f"average rate: {stats['rate_hz']:.3f} Hz\n\tmin: {stats['min_s']:.4f}s "
            f"max: {stats['max_s']:.4f}s std dev: {stats['std_s']:.5f}s "
            f"window: {stats['window']}")


def main(ctx: ServiceContext) -> int:
    """Print the publishing rate of KEY every second over a sliding window.

    Exit 1 when nothing arrived within --timeout (or no rate within
    --duration), saying whether anything could match the key at all.
    """
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    stamps: deque[float] = deque(maxlen=args.window)
    received = 0
    lock = threading.Lock()

    def on_sample(_key: str, _payload: bytes, _encoding: str) -> None:
        nonlocal received
        with lock:
            stamps.append(time.monotonic())
            received += 1

    first_by = probing.deadline(args.timeout)
    end = probing.deadline(args.duration)
    why = ""
    period = 0.1 if args.json else 1.0  # --json prints once: only check the deadlines
    with ctx.probe(args.timeout) as node:
        node.subscribe_raw(key, on_sample)
        hint_at = (time.monotonic() + CONNECT_TIMEOUT_S
                   if args.timeout is None else float("inf"))
        while not ctx.stop.wait(period) and time.monotonic() < end:
            with lock:
                report = rate_report(list(stamps))
                nothing = received == 0
            if nothing and time.monotonic() >= first_by:
                break
            if nothing and time.monotonic() > hint_at:
                hint_at = float("inf")  # running until stopped: say it once, keep waiting
                print(f"buddybot hz: nothing yet: {probing.silence_reason(node, key)}",
                      file=sys.stderr, flush=True)
            if not args.json:
                print(report or "no new messages", flush=True)
        with lock:
            nothing = received == 0
            stats = rate_stats(list(stamps))
        if nothing and not ctx.stop.is_set():
            why = probing.silence_reason(node, key)
    if args.json:
        print(json.dumps({"key": key, "received": received, **(stats or {"rate_hz": None})}))
    if why:
        waited = args.timeout if time.monotonic() >= first_by else args.duration
        print(f"buddybot hz: nothing received on {key} within {waited:g} s: {why}",
              file=sys.stderr)
        return 1
    if args.duration and stats is None:
        return 1
    return 0
