"""The `buddybot` command: the verbs robot people know from `ros2`.

    buddybot up [--sim] [--no-browser]     the whole robot on this machine
    buddybot router [--listen ENDPOINT]     a Zenoh router
    buddybot run SERVICE [options]          one service
    buddybot echo|hz|pub|call KEY ...       probe the robot
    buddybot nodes | keys | config          what runs, what exists, what is set
    buddybot schemas [--check]              regenerate / check schemas/
    buddybot radar ...                      LD2410 configuration tools

Exit status: 0 success, 1 failure at run time, 2 bad usage or config.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from buddybot import __version__
from buddybot.core import registry
from buddybot.core.config import DEFAULT_ENDPOINT, to_toml_dict
from buddybot.core.errors import ConfigError
from buddybot.core.service import ServiceContext, add_common_arguments, resolve, run_main

Handler = Callable[[ServiceContext], int]


def _tool(handler_name: str) -> Handler:
    def run(ctx: ServiceContext) -> int:
        from buddybot.core import tools

        try:
            return int(getattr(tools, handler_name)(ctx))
        except tools.ToolError as exc:
            print(f"buddybot {ctx.name}: {exc}", file=sys.stderr)
            return 2

    return run


def _router(ctx: ServiceContext) -> int:
    from buddybot.core.router import run_router

    run_router(ctx.args.listen or [DEFAULT_ENDPOINT], ctx.stop, ctx.args.zenoh_config)
    return 0


def _up(ctx: ServiceContext) -> int:
    from buddybot.core.launch import up

    return up(ctx)


def _config(ctx: ServiceContext) -> int:
    import tomli_w

    data = to_toml_dict(ctx.config)
    data["robot"]["id"] = ctx.robot  # type: ignore[index]
    data["zenoh"]["connect"] = ctx.connect  # type: ignore[index]
    print(tomli_w.dumps(_drop_none(data)), end="")
    return 0


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    return value


def _schemas(ctx: ServiceContext) -> int:
    from buddybot.core import schemas

    out = Path(ctx.args.out)
    if ctx.args.check:
        stale = schemas.drift(out)
        for name in stale:
            print(f"out of date: {out / name}", file=sys.stderr)
        return 1 if stale else 0
    for path in schemas.write(out):
        print(path)
    return 0


def _keys(ctx: ServiceContext) -> int:
    from buddybot.core.tools import key_list

    return key_list(ctx)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="buddybot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action="version", version=f"buddybot {__version__}")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)

    def verb(name: str, handler: Handler, help_text: str) -> argparse.ArgumentParser:
        sub = verbs.add_parser(name, help=help_text, description=help_text)
        add_common_arguments(sub)
        sub.set_defaults(handler=handler)
        return sub

    p = verb("up", _up, "run the whole robot: router on loopback + every service")
    p.add_argument("--sim", action="store_true", help="simulated radar and camera")
    p.add_argument("--no-browser", action="store_true", help="serve the eye pages only")
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"where the router listens (default {DEFAULT_ENDPOINT})")
    p.add_argument("--only", action="append", metavar="SERVICE",
                   help="start only these services (repeatable)")
    p.add_argument("--status-period", type=float, default=5.0, metavar="S",
                   help="print a status line every S seconds (0: never)")

    p = verb("router", _router, "run a Zenoh router")
    p.add_argument("--listen", action="append", metavar="ENDPOINT",
                   help=f"listen endpoint (repeatable; default {DEFAULT_ENDPOINT})")
    p.add_argument("--zenoh-config", metavar="FILE",
                   help="Zenoh JSON5 config to start from (TLS, access control)")

    run = verbs.add_parser(
        "run", help="run one service", description="Run one service as this process. "
        "`buddybot run SERVICE --help` lists its options.\n\nservices:\n" + "\n".join(
            f"  {e.name:<16}{e.help}" for e in registry.SERVICES),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("service", choices=[e.name for e in registry.SERVICES], metavar="SERVICE")
    run.add_argument("service_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    run.set_defaults(handler=None)

    p = verb("echo", _tool("echo"), "print decoded messages on KEY")
    p.add_argument("key", help="key (prefix buddybot/<robot>/ optional; wildcards allowed)")
    p.add_argument("--count", "-n", type=int, default=0, help="exit after N messages")
    p.add_argument("--timeout", type=float, default=None, help="exit after this many seconds")
    p.add_argument("--show-key", action="store_true", help="print the key before each message")

    p = verb("hz", _tool("hz"), "print the publishing rate of KEY")
    p.add_argument("key")
    p.add_argument("--window", type=int, default=100, help="samples in the window")
    p.add_argument("--duration", type=float, default=None, help="exit after this many seconds")

    p = verb("pub", _tool("pub"), "validate and publish one message on KEY")
    p.add_argument("key")
    p.add_argument("message", help="JSON object; stamp_ns defaults to now")
    p.add_argument("--rate", type=float, default=0.0, help="repeat at this rate (Hz)")
    p.add_argument("--times", type=int, default=0, help="with --rate: stop after N messages")
    p.add_argument("--wait", type=float, default=2.0,
                   help="seconds to wait for a subscriber before the first put")

    p = verb("call", _tool("call"), "query a service (or send an action goal) and print the reply")
    p.add_argument("key")
    p.add_argument("request", nargs="?", default="{}", help="JSON request (default {})")
    p.add_argument("--timeout", type=float, default=5.0)

    p = verb("nodes", _tool("nodes"), "list live nodes (liveliness tokens)")
    p.add_argument("--all-robots", action="store_true", help="every robot on the router")
    p.add_argument("--timeout", type=float, default=2.0)

    verb("keys", _keys, "list the key catalogue")
    verb("config", _config, "print the effective configuration")

    p = verb("schemas", _schemas, "write (or --check) the JSON schemas in schemas/")
    p.add_argument("--out", default="schemas", help="folder (default: schemas)")
    p.add_argument("--check", action="store_true", help="exit 1 if the folder is out of date")

    for tool in registry.TOOLS:
        sub = verbs.add_parser(tool.name, help=tool.help, add_help=False)
        sub.add_argument("tool_args", nargs=argparse.REMAINDER)
        sub.set_defaults(handler=None, tool=tool)
    return parser


def _extension(entry: registry.Entry, prog: str, argv: list[str]) -> int:
    """Run a registered service or tool module: its own parser, shared options."""
    module = entry.load()
    parser = argparse.ArgumentParser(prog=prog, description=entry.help)
    add_common_arguments(parser)
    module.add_arguments(parser)
    args = parser.parse_args(argv)
    return run_main(entry.name, args, module.run)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    tool = next((t for t in registry.TOOLS if argv and argv[0] == t.name), None)
    if tool is not None:  # its own parser sees everything, `--help` included
        return _extension(tool, f"buddybot {tool.name}", argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.verb == "run":
        entry = registry.service(args.service)
        assert entry is not None
        if not entry.exists():
            print(f"buddybot run: service {entry.name} is not installed yet", file=sys.stderr)
            return 2
        return _extension(entry, f"buddybot run {entry.name}", args.service_args)
    if getattr(args, "tool", None) is not None:
        return _extension(args.tool, f"buddybot {args.tool.name}", args.tool_args)
    if args.verb in ("keys", "schemas"):
        return int(args.handler(ServiceContext(args.verb, args, None, "buddy", [])))  # type: ignore[arg-type]
    if args.verb == "config":
        try:
            ctx = resolve(args, "config")
        except ConfigError as exc:
            print(f"buddybot: config error: {exc}", file=sys.stderr)
            return 2
        return _config(ctx)
    return run_main(args.verb, args, args.handler)


if __name__ == "__main__":
    sys.exit(main())
