"""`buddybot pub KEY MESSAGE`: validate a message against KEY's type and publish it."""

from __future__ import annotations

import argparse
import sys
import time

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import options
from buddybot.runtime.errors import UsageError
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.session import CONNECT_TIMEOUT_S
from buddybot.tools import probing

HELP = "validate and publish one message on KEY"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_key_argument(parser, wildcards=False)
    parser.add_argument("message", help="JSON object; stamp_ns defaults to now; enum fields "
                        'take names or numbers ({"action": "EYE_SLEEP"})')
    parser.add_argument("--rate", type=float, default=0.0, help="repeat at this rate (Hz)")
    parser.add_argument("--times", type=int, default=0,
                        help="with --rate: stop after N messages")
    parser.add_argument("--wait", type=float, default=2.0,
                        help="seconds to wait for a subscriber before the first put "
                             "(none by then: a warning, and the message goes nowhere)")
    options.add_timeout_argument(parser, CONNECT_TIMEOUT_S, "the connection")


def main(ctx: ServiceContext) -> int:
    """Validate a message against KEY's type, then publish it (once, or at --rate).

    No subscriber matching KEY after --wait: a warning on stderr (a latched
    key still keeps the value for later subscribers), exit status 0.
    """
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    entry = keys.lookup_absolute(key)
    if not isinstance(entry, keys.Topic):
        raise UsageError(f"{args.key}: not a topic of the catalogue (see `buddybot keys`)")
    if "*" in key:
        raise UsageError(f"{args.key}: cannot publish on a wildcard key")
    msg = probing.parse_message(entry.type, args.message)
    sent = 0
    with ctx.probe(args.timeout) as node, \
            node.raw_publisher(key, entry.encoding) as publisher:
        # Give discovery a moment so the first put reaches existing subscribers.
        if not publisher.wait_for_subscribers(args.wait, ctx.stop) and not ctx.stop.is_set():
            print(f"buddybot pub: warning: no subscriber matches {key} "
                  f"(waited {args.wait:g} s): nobody receives this", file=sys.stderr, flush=True)
        while not ctx.stop.is_set():
            if hasattr(msg, "stamp_ns") and args.rate and "stamp_ns" not in args.message:
                msg = msgspec.structs.replace(msg, stamp_ns=m.now_ns())
            publisher.put(entry.codec.encode(msg))
            sent += 1
            if not args.rate or (args.times and sent >= args.times):
                break
            ctx.stop.wait(1.0 / args.rate)
        time.sleep(0.1)  # let the last put leave before the session closes
    print(f"published {sent} x {type(msg).__name__} on {key}", file=sys.stderr)
    return 0
