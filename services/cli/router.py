"""`buddybot router`: a Zenoh router (the robot's own, or one per host).

A listen port that is already taken ends it at once with exit status 1 and
one line naming the endpoint and who holds it (a Zenoh router with whose
nodes, or a stranger, and the local process when psutil can tell): the same
look as `doctor`'s router-port check (`buddybot.supervisor.router.busy_port`).
"""

from __future__ import annotations

import argparse

from buddybot.runtime.config import DEFAULT_ENDPOINT
from buddybot.runtime.service import ServiceContext

HELP = "run a Zenoh router"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help=f"listen endpoint (repeatable; default {DEFAULT_ENDPOINT})")
    parser.add_argument("--zenoh-config", metavar="FILE",
                        help="Zenoh JSON5 config to start from (TLS, access control)")


def main(ctx: ServiceContext) -> int:
    from buddybot.supervisor.router import run_router

    run_router(ctx.args.listen or [DEFAULT_ENDPOINT], ctx.stop, ctx.args.zenoh_config)
    return 0
