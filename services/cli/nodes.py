"""`buddybot nodes`: the live nodes of the robot, from their liveliness tokens."""

from __future__ import annotations

import argparse
import json
import sys

from buddybot.runtime import options
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.session import CONNECT_TIMEOUT_S
from buddybot.tools import probing

HELP = "list live nodes (liveliness tokens)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--all-robots", action="store_true", help="every robot on the router")
    options.add_timeout_argument(parser, CONNECT_TIMEOUT_S,
                                 "connection and liveliness query together")
    options.add_json_argument(
        parser, 'one JSON document: {"robot": ..., "nodes": {name: [instances]}}')


def main(ctx: ServiceContext) -> int:
    """List live nodes; --timeout covers connecting and the liveliness query.

    None at all exits 1 with a line on stderr (a wrong --robot, nothing
    started, or the router's access control hiding them), so a script can
    ask "is the robot up?" by the status alone.
    """
    args = ctx.args
    end = probing.deadline(args.timeout)
    with ctx.probe(args.timeout) as node:
        found = node.node_instances(all_robots=args.all_robots, timeout=probing.left(end))
    if args.json:
        print(json.dumps({"robot": "*" if args.all_robots else ctx.robot,
                          "nodes": {name: sorted(found[name]) for name in sorted(found)}}))
    else:
        for name in sorted(found):
            instances = sorted(found[name])
            if len(instances) > 1:
                print(f"{name}  DUPLICATE: {len(instances)} instances ({', '.join(instances)})")
            else:
                print(name)
    if not found:
        whose = "any robot" if args.all_robots else f"robot {ctx.robot!r}"
        print(f"buddybot nodes: no live node of {whose} on {', '.join(ctx.connect)} "
              "(nothing started, a wrong --robot, or the router's access control hides them)",
              file=sys.stderr)
        return 1
    return 0
