"""`buddybot param list|get|set|dump|load NODE ...`: a running node's settings (`ros2 param`).

The node answers `params/<node>` itself (`runtime.params.LiveSettings`), so
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

from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import nesting, options
from buddybot.runtime.errors import NoReplyError, ServiceError, UsageError
from buddybot.runtime.service import ServiceContext

HELP = "list, get, set, dump or load a running node's parameters (its settings)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, dest="op", shared=_shared)


def _shared(parser: argparse.ArgumentParser) -> None:
    """Options every sub-verb accepts, before or after its name (`--json` and
    `-o` are read by the sub-verbs that print a table or write a file)."""
    options.add_answer_timeout(parser)
    options.add_json_argument(parser)
    parser.add_argument("--output", "-o", metavar="FILE", help="dump: write FILE, not stdout")


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


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
    with ctx.probe() as node:
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
        text = Path(path).read_bytes()
        nesting.check_depth(text, toml=True)
        data = msgspec.toml.decode(text)
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror}") from None
    except (msgspec.DecodeError, nesting.TooDeep) as exc:
        raise UsageError(f"{path}: not valid TOML: {exc}") from None
    values = data.get(table) if isinstance(data, dict) else None
    if not isinstance(values, dict):
        raise UsageError(f"{path}: no [{table}] table")
    return values


def _add_list(parser: argparse.ArgumentParser) -> None:
    options.add_node_argument(parser)


def _list(ctx: ServiceContext) -> int:
    reply = request(ctx, ctx.args.node, m.ParamRequest(op="list"))
    if ctx.args.json:
        print(msgspec.json.encode(reply.params).decode())
    else:
        print(f"[{reply.table}] of {reply.node}")
        print("\n".join(table_lines(reply.params)))
    return 0


def _add_get(parser: argparse.ArgumentParser) -> None:
    options.add_node_argument(parser)
    parser.add_argument("field", help="the parameter (a field of the node's settings)")


def _get(ctx: ServiceContext) -> int:
    reply = request(ctx, ctx.args.node, m.ParamRequest(op="get", name=ctx.args.field))
    info = reply.params[0]
    print(msgspec.json.encode(info).decode() if ctx.args.json else _value(info.value))
    return 0


def _add_set(parser: argparse.ArgumentParser) -> None:
    options.add_node_argument(parser)
    parser.add_argument("field", help="the parameter (a field of the node's settings)")
    parser.add_argument("value", help="its new value: JSON, else a string")


def _set(ctx: ServiceContext) -> int:
    field, text = ctx.args.field, ctx.args.value
    reply = request(ctx, ctx.args.node,
                    m.ParamRequest(op="set", values={field: parse_value(text)}))
    now = reply.params[0].value if reply.params else None
    state = "applied" if reply.changed else "unchanged"
    print(f"{reply.table}.{field} = {_value(now)} ({state})")
    return 0


def _add_dump(parser: argparse.ArgumentParser) -> None:
    options.add_node_argument(parser)


def _dump(ctx: ServiceContext) -> int:
    text = dump_toml(request(ctx, ctx.args.node, m.ParamRequest(op="list")))
    if ctx.args.output:
        Path(ctx.args.output).write_bytes(text)
    else:
        sys.stdout.write(text.decode())
    return 0


def _add_load(parser: argparse.ArgumentParser) -> None:
    options.add_node_argument(parser)
    parser.add_argument("file", help="a TOML file (its table of the node's settings is applied)")


def _load(ctx: ServiceContext) -> int:
    name = ctx.args.node
    table = request(ctx, name, m.ParamRequest(op="list")).table
    values = load_table(ctx.args.file, table)
    reply = request(ctx, name, m.ParamRequest(op="set", values=values))
    print(f"[{table}] loaded into {name}: "
          + (", ".join(reply.changed) + " changed" if reply.changed else "nothing changed"))
    return 0


SUBVERBS = (
    SubVerb("list", "every parameter: value, type, range, live or restart", _add_list, _list,
            "NODE"),
    SubVerb("get", "one parameter's value", _add_get, _get, "NODE FIELD"),
    SubVerb("set", "change one parameter (live ones apply at once)", _add_set, _set,
            "NODE FIELD VALUE"),
    SubVerb("dump", "the node's table as TOML that --config accepts", _add_dump, _dump, "NODE"),
    SubVerb("load", "apply the node's table of a TOML file", _add_load, _load, "NODE FILE"),
)
