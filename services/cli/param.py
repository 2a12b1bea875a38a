"""`buddybot param list|get|set|dump|load NODE ...`: a running node's settings (`ros2 param`).

The node answers `params/<node>` itself (`core.params.LiveSettings`), so
what is shown is what it runs with, and a change is validated by the
node against its own settings type. Fields marked live apply at once;
the others are refused (change the config file and restart). `dump`
writes the node's table as TOML that `--config` accepts, `load FILE`
applies that table (other tables in FILE are ignored).

Exit status: 0 done, 1 refused or no answer within `--timeout`, 2 bad usage
(wrong arguments, an unknown field, an unreadable file).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import NoReplyError, ServiceError, UsageError
from buddybot.runtime.service import ServiceContext
from buddybot.tools import probing

HELP = "list, get, set, dump or load a running node's parameters (its settings)"
OPS = ("list", "get", "set", "dump", "load")
ARITY = {"list": 0, "get": 1, "set": 2, "dump": 0, "load": 1}
USAGE = {"list": "", "get": " FIELD", "set": " FIELD VALUE", "dump": "", "load": " FILE"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("op", choices=OPS, help="what to do")
    parser.add_argument("node", help="node name (see `buddybot nodes`)")
    parser.add_argument("args", nargs="*", metavar="ARG",
                        help="get FIELD | set FIELD VALUE (JSON, else a string) | load FILE")
    parser.add_argument("--timeout", type=float, default=5.0,
                        help="seconds to wait for the node's answer (then exit 1)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.add_argument("--output", "-o", metavar="FILE", help="dump: write FILE, not stdout")


def parse_value(text: str) -> Any:
    """A value as typed: JSON (`1.5`, `true`, `["a"]`, `null`), else the text itself."""
    try:
        return msgspec.json.decode(text)
    except msgspec.DecodeError:
        return text


def request(ctx: ServiceContext, node_name: str, req: m.ParamRequest) -> m.ParamReply:
    """One call to `params/<node>`; ServiceError (exit 1) when nobody answers."""
    if not keys.valid_robot_id(node_name):
        raise UsageError(f"{node_name!r} is not a node name")
    with probing.probe(ctx) as node:
        try:
            reply: m.ParamReply = node.call(keys.PARAMS, req, timeout=ctx.args.timeout,
                                            node=node_name)
        except NoReplyError:
            raise ServiceError(
                f"node {node_name} did not answer on {keys.PARAMS.key(node=node_name)} within "
                f"{ctx.args.timeout:g} s (not running, or it exposes no parameters)") from None
    if reply.error:
        if reply.unknown:
            raise UsageError(f"{node_name}: {reply.error}")
        raise ServiceError(f"{node_name}: {reply.error}")
    return reply


def _value(value: Any) -> str:
    return msgspec.json.encode(value).decode()


def table_lines(params: list[m.ParamInfo]) -> list[str]:
    """One aligned line per field: name, value, type, range, live or restart."""
    rows = [(p.name, _value(p.value), p.type, p.range or "-", "live" if p.live else "restart")
            for p in params]
    widths = [max([len(r[i]) for r in rows] + [1]) for i in range(4)]
    return ["  ".join(c.ljust(w) for c, w in zip(r[:4], widths, strict=True)) + "  " + r[4]
            for r in rows]


def dump_toml(reply: m.ParamReply) -> bytes:
    """The node's table as TOML for `--config` (None values left out: TOML has no null)."""
    table = {p.name: p.value for p in reply.params if p.value is not None}
    head = f"# buddybot param dump {reply.node}\n".encode()
    return head + msgspec.toml.encode({reply.table: table})


def load_table(path: str, table: str) -> dict[str, Any]:
    """The `[table]` of a TOML file (UsageError naming the file when it cannot be used)."""
    try:
        data = msgspec.toml.decode(Path(path).read_bytes())
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror}") from None
    except msgspec.DecodeError as exc:
        raise UsageError(f"{path}: not valid TOML: {exc}") from None
    values = data.get(table) if isinstance(data, dict) else None
    if not isinstance(values, dict):
        raise UsageError(f"{path}: no [{table}] table")
    return values


def main(ctx: ServiceContext) -> int:
    args = ctx.args
    if len(args.args) != ARITY[args.op]:
        raise UsageError(f"usage: buddybot param {args.op} NODE{USAGE[args.op]}")
    name = args.node
    if args.op == "list":
        reply = request(ctx, name, m.ParamRequest(op="list"))
        if args.json:
            print(msgspec.json.encode(reply.params).decode())
        else:
            print(f"[{reply.table}] of {reply.node}")
            print("\n".join(table_lines(reply.params)))
    elif args.op == "get":
        reply = request(ctx, name, m.ParamRequest(op="get", name=args.args[0]))
        info = reply.params[0]
        print(msgspec.json.encode(info).decode() if args.json else _value(info.value))
    elif args.op == "set":
        field, text = args.args
        reply = request(ctx, name, m.ParamRequest(op="set", values={field: parse_value(text)}))
        now = reply.params[0].value if reply.params else None
        state = "applied" if reply.changed else "unchanged"
        print(f"{reply.table}.{field} = {_value(now)} ({state})")
    elif args.op == "dump":
        reply = request(ctx, name, m.ParamRequest(op="list"))
        text = dump_toml(reply)
        if args.output:
            Path(args.output).write_bytes(text)
        else:
            sys.stdout.write(text.decode())
    else:  # load
        table = request(ctx, name, m.ParamRequest(op="list")).table
        values = load_table(args.args[0], table)
        reply = request(ctx, name, m.ParamRequest(op="set", values=values))
        print(f"[{table}] loaded into {name}: "
              + (", ".join(reply.changed) + " changed" if reply.changed else "nothing changed"))
    return 0
