"""`buddybot echo KEY`: print every message on KEY, decoded (like `ros2 topic echo`)."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import threading
import time

from buddybot.core import keys, tools
from buddybot.core.describe import describe
from buddybot.core.service import ServiceContext

HELP = "print decoded messages on KEY"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", help="key (prefix buddybot/<robot>/ optional; wildcards allowed)")
    parser.add_argument("--count", "-n", type=int, default=0, help="exit after N messages")
    parser.add_argument("--timeout", type=float, default=None,
                        help="exit after this many seconds")
    parser.add_argument("--show-key", action="store_true",
                        help="print the key before each message")


def main(ctx: ServiceContext) -> int:
    """Print every message on KEY, decoded; latched values arrive at once."""
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    count = 0
    done = threading.Event()
    closed = threading.Event()
    lock = threading.Lock()

    def on_sample(sample_key: str, payload: bytes, _encoding: str) -> None:
        nonlocal count
        text = describe(sample_key, payload)
        with lock:
            if done.is_set():
                return
            line = f"{sample_key}: {text}" if args.show_key else text
            try:
                print(line, flush=True)
            except (BrokenPipeError, ValueError):  # `| head` closed the pipe: stop quietly
                closed.set()
                done.set()
                return
            count += 1
            if args.count and count >= args.count:
                done.set()

    with tools.probe(ctx) as node:
        node.subscribe_raw(key, on_sample, history=tools.is_latched(key) or "*" in key)
        end = tools.deadline(args.timeout)
        while not done.is_set() and not ctx.stop.is_set() and time.monotonic() < end:
            done.wait(0.1)
    if closed.is_set():
        with contextlib.suppress(OSError):  # no traceback at exit for the closed stdout
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115
        return 0
    if args.count and count < args.count:
        print(f"buddybot echo: got {count} of {args.count} messages", file=sys.stderr)
        return 1
    return 0
