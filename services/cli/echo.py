"""`buddybot echo KEY`: print every message on KEY, decoded (like `ros2 topic echo`)."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import threading
import time

from buddybot.contract import keys
from buddybot.contract.describe import describe
from buddybot.runtime import options
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.session import CONNECT_TIMEOUT_S
from buddybot.tools import probing

HELP = "print decoded messages on KEY"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_key_argument(parser)
    parser.add_argument("--count", "-n", type=int, default=0, help="exit after N messages")
    options.add_timeout_argument(parser, None, "exit after S seconds; exit 1 if nothing arrived")
    parser.add_argument("--show-key", action="store_true",
                        help="print the key before each message")
    parser.add_argument("--raw", action="store_true",
                        help="enum fields as numbers (as on the wire), not names")


def main(ctx: ServiceContext) -> int:
    """Print every message on KEY, decoded; latched values arrive at once.

    Exit 1 when nothing (or fewer than --count) arrived within --timeout,
    saying whether anything could match the key at all.
    """
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    end = probing.deadline(args.timeout)
    count = 0
    done = threading.Event()
    closed = threading.Event()
    lock = threading.Lock()

    def on_sample(sample_key: str, payload: bytes, _encoding: str) -> None:
        nonlocal count
        text = describe(sample_key, payload, names=not args.raw)
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

    why = ""
    stopped = False  # Ctrl-C (closing the node sets ctx.stop too: look before)
    with ctx.probe(args.timeout) as node:
        node.subscribe_raw(key, on_sample, history=probing.is_latched(key) or "*" in key)
        hint_at = time.monotonic() + CONNECT_TIMEOUT_S
        while not done.is_set() and not ctx.stop.is_set() and time.monotonic() < end:
            done.wait(0.1)
            if args.timeout is None and count == 0 and time.monotonic() > hint_at:
                hint_at = float("inf")  # running until stopped: say it once, keep waiting
                print(f"buddybot echo: nothing yet: {probing.silence_reason(node, key)}",
                      file=sys.stderr, flush=True)
        stopped = ctx.stop.is_set()
        if count == 0 and not closed.is_set() and not stopped:
            why = probing.silence_reason(node, key)
    if closed.is_set():
        with contextlib.suppress(OSError):  # no traceback at exit for the closed stdout
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115
        return 0
    if stopped:
        return 0
    if count == 0:
        got = f"got 0 of {args.count} messages: " if args.count else ""
        print(f"buddybot echo: {got}nothing received on {key} within {args.timeout:g} s: "
              f"{why}", file=sys.stderr)
        return 1
    if args.count and count < args.count:
        print(f"buddybot echo: got {count} of {args.count} messages", file=sys.stderr)
        return 1
    return 0
