"""`buddybot call KEY [REQUEST]`: query a service or send an action goal, print the reply."""

from __future__ import annotations

import argparse
import sys

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.contract.describe import summarize
from buddybot.runtime import options
from buddybot.runtime.errors import UsageError
from buddybot.runtime.service import ServiceContext
from buddybot.tools import probing

HELP = "query a service (or send an action goal) and print the reply"

REFUSAL_FIELDS = ("accepted", "success")
"""Reply fields that say the service refused or failed (false -> exit status 1)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_key_argument(parser, wildcards=False)
    parser.add_argument("request", nargs="?", default="{}",
                        help="JSON request (default {}); enum fields take names or numbers")
    options.add_timeout_argument(parser, 5.0, "connection and reply together")
    parser.add_argument("--raw", action="store_true",
                        help="enum fields of the reply as numbers, not names")


def refusal(reply: object) -> str | None:
    """Why a decoded reply means failure (`accepted`/`success` false), else None."""
    for name in REFUSAL_FIELDS:
        if getattr(reply, name, True) is False:
            detail = getattr(reply, "message", "") or ""
            return f"{name}: false" + (f" ({detail})" if detail else "")
    return None


def main(ctx: ServiceContext) -> int:
    """Query a service or action goal of the catalogue and print the reply.

    A failed call raises ServiceError: exit status 1 (run_main). A reply
    that says no (`accepted: false`, `success: false`) is printed, and
    exits 1 too, so scripts can trust the status. --timeout covers
    connecting and the reply together.
    """
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    entry = keys.lookup_absolute(key)
    if not isinstance(entry, keys.Service):
        raise UsageError(f"{args.key}: not a service of the catalogue (see `buddybot keys`)")
    request = probing.parse_message(entry.request, args.request)
    end = probing.deadline(args.timeout)
    with ctx.probe(args.timeout) as node:
        remaining = round(probing.left(end, 0.1), 1) if args.timeout else 5.0
        reply = node.call_key(key, entry, request, timeout=remaining)
    print(summarize(reply, names=not args.raw) if isinstance(reply, m.Message)
          else msgspec.json.encode(reply).decode(), flush=True)
    why = refusal(reply)
    if why is not None:
        print(f"buddybot call: {key} refused: {why}", file=sys.stderr)
        return 1
    return 0


