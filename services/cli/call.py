"""`buddybot call KEY [REQUEST]`: query a service or send an action goal, print the reply."""

from __future__ import annotations

import argparse

import msgspec

from buddybot.core import keys, tools
from buddybot.core.errors import UsageError
from buddybot.core.service import ServiceContext

HELP = "query a service (or send an action goal) and print the reply"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key")
    parser.add_argument("request", nargs="?", default="{}", help="JSON request (default {})")
    parser.add_argument("--timeout", type=float, default=5.0)


def main(ctx: ServiceContext) -> int:
    """Query a service or action goal of the catalogue and print the reply.

    A refused or failed call raises ServiceError: exit status 1 (run_main).
    """
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    entry = tools.catalogue_entry(key)
    if not isinstance(entry, keys.Service):
        raise UsageError(f"{args.key}: not a service of the catalogue (see `buddybot keys`)")
    request = tools.parse_message(entry.request, args.request)
    with tools.probe(ctx) as node:
        reply = node.call_key(key, entry, request, timeout=args.timeout)
    print(msgspec.json.encode(reply).decode(), flush=True)
    return 0
