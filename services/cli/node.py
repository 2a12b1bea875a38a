"""`buddybot node info NAME`: what a running node publishes, subscribes and serves.

The node reports it itself (`node_info/<name>`, answered by every node from
the handles it holds open: `Node.declared()`), so this is what the process
really declared, wildcards included, not what a catalogue expects. Its
parameters come from `params/<name>` when it exposes them.
"""

from __future__ import annotations

import argparse

import msgspec

from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import options
from buddybot.runtime.errors import NoReplyError, ServiceError, UsageError
from buddybot.runtime.service import ServiceContext

HELP = "what a running node publishes, subscribes, serves, and its parameters"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, shared=_shared)


def _shared(parser: argparse.ArgumentParser) -> None:
    """Accepted before or after the sub-verb's name."""
    options.add_answer_timeout(parser)
    options.add_json_argument(parser)


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


def _add_info(parser: argparse.ArgumentParser) -> None:
    options.add_node_argument(parser)


class Report(msgspec.Struct, kw_only=True):
    info: m.NodeInfo
    params: list[m.ParamInfo] | None
    """None: the node exposes no parameters."""
    table: str = ""


def lines(report: Report) -> list[str]:
    info = report.info
    out = [f"node {info.node} (instance {info.instance})"]
    for title, entries in (("publishers", info.publishers),
                           ("subscriptions", info.subscriptions),
                           ("services", info.services)):
        out.append(f"{title}:")
        out.extend(f"  {key}" for key in entries or ["(none)"])
    if report.params is None:
        out.append("parameters: (none exposed)")
    else:
        out.append(f"parameters [{report.table}]:")
        out.extend(f"  {p.name} = {msgspec.json.encode(p.value).decode()}"
                   f"  ({'live' if p.live else 'restart'})" for p in report.params)
    return out


def info(ctx: ServiceContext) -> int:
    args = ctx.args
    name = args.node
    if not keys.valid_robot_id(name):
        raise UsageError(f"{name!r} is not a node name")
    with ctx.probe() as node:
        try:
            info: m.NodeInfo = node.call(keys.NODE_INFO, m.Trigger(), timeout=args.timeout,
                                         node=name)
        except NoReplyError:
            raise ServiceError(f"node {name} did not answer within {args.timeout:g} s "
                               "(is it running? see `buddybot nodes`)") from None
        report = Report(info=info, params=None)
        if keys.PARAMS.key(node=name) in info.services:
            reply: m.ParamReply = node.call(keys.PARAMS, m.ParamRequest(op="list"),
                                            timeout=args.timeout, node=name)
            report.params, report.table = reply.params, reply.table
    if args.json:
        print(msgspec.json.encode(report).decode())
    else:
        print("\n".join(lines(report)))
    return 0


SUBVERBS = (SubVerb("info", HELP, _add_info, info),)
