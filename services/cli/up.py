"""`buddybot up`: the whole robot on this machine (router on loopback + every service)."""

from __future__ import annotations

import argparse

from buddybot.core.config import DEFAULT_ENDPOINT
from buddybot.core.service import ServiceContext

HELP = "run the whole robot: router on loopback + every service"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sim", action="store_true", help="simulated radar and camera")
    parser.add_argument("--no-browser", action="store_true", help="serve the eye pages only")
    parser.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help=f"where the router listens (default {DEFAULT_ENDPOINT})")
    parser.add_argument("--only", action="append", metavar="SERVICE",
                        help="start only these services (repeatable)")
    parser.add_argument("--status-period", type=float, default=5.0, metavar="S",
                        help="print a status line every S seconds (0: never)")


def main(ctx: ServiceContext) -> int:
    from buddybot.core.launch import up  # the supervisor: loaded only by this verb

    return up(ctx)
