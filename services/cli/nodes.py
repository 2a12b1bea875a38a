"""`buddybot nodes`: the live nodes of the robot, from their liveliness tokens."""

from __future__ import annotations

import argparse

from buddybot.core import tools
from buddybot.core.service import ServiceContext

HELP = "list live nodes (liveliness tokens)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--all-robots", action="store_true", help="every robot on the router")
    parser.add_argument("--timeout", type=float, default=2.0)


def main(ctx: ServiceContext) -> int:
    with tools.probe(ctx) as node:
        found = node.node_instances(all_robots=ctx.args.all_robots, timeout=ctx.args.timeout)
    for name in sorted(found):
        instances = sorted(found[name])
        if len(instances) > 1:
            print(f"{name}  DUPLICATE: {len(instances)} instances ({', '.join(instances)})")
        else:
            print(name)
    return 0
