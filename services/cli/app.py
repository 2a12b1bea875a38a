"""`buddybot app run|new|list`: run an app, start one from a template, see them all.

`run` is the app runner (`buddybot.apps.runner`): the same process `up`
starts for each app of `[apps]`. `new` writes a file that runs as generated.
`list` shows the installed apps (entry-point group `buddybot.apps`), the
config's `[apps]`, and the apps running now: the robot's live nodes that are
not one of its services.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from pathlib import Path

from buddybot.apps import loading, runner, template
from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.runtime import options, registry
from buddybot.runtime.errors import UsageError
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.session import CONNECT_TIMEOUT_S, RouterUnreachable
from buddybot.tools import probing

HELP = "apps: run one (FILE, MODULE or NAME), start one from a template, list them"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, dest="op")


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


# -- run --

def _add_run(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("app", metavar="FILE|MODULE|NAME",
                        help="an app file (app.py[:Class]), a module (pkg.mod[:Class]) or "
                        "the name of an installed app")
    parser.add_argument("--name", help="its node name (default: the class's `name`, else the "
                        "file's stem, the module's last part, the installed name)")
    parser.add_argument("--grace", type=float, default=runner.GRACE_S, metavar="S",
                        help="seconds run() has to return once stopped (default %(default)g)")


def _run(ctx: ServiceContext) -> int:
    args = ctx.args
    if args.grace < 0:
        raise UsageError(f"--grace: {args.grace:g} is negative")
    return runner.main(ctx, args.app, args.name, args.grace)


# -- new --

def _add_new(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("app_name", metavar="NAME", help="the app's name: NAME.py, its class "
                        "and its node name")
    parser.add_argument("--dir", default=".", help="where to write NAME.py (default: here)")


def _new(ctx: ServiceContext) -> int:
    name, folder = ctx.args.app_name, Path(ctx.args.dir)
    try:
        text = template.render(name)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if not folder.is_dir():
        raise UsageError(f"--dir: {folder} is not a folder")
    path = folder / f"{name}.py"
    if path.exists():
        raise UsageError(f"{path} already exists: not overwritten")
    path.write_text(text)
    print(f"wrote {path}; run it with: buddybot app run {path}")
    return 0


# -- list --

def _add_list(parser: argparse.ArgumentParser) -> None:
    options.add_timeout_argument(parser, CONNECT_TIMEOUT_S,
                                 "connection and liveliness query together")
    options.add_json_argument(
        parser, 'one JSON document: {"installed": {name: target}, "config": [spec], '
        '"running": [name] or null when no router answered}')


def running_apps(found: Iterable[str]) -> list[str]:
    """The live node names that are not services of the robot: its apps."""
    services = {e.name for e in registry.SERVICES}
    return sorted(name for name in found if name not in services)


def _list(ctx: ServiceContext) -> int:
    args = ctx.args
    installed = loading.installed_apps()
    configured = list(ctx.config.apps.run)
    running: list[str] | None
    problem = ""
    end = probing.deadline(args.timeout)
    try:
        with ctx.probe(args.timeout) as node:
            running = running_apps(node.node_instances(timeout=probing.left(end)))
    except RouterUnreachable as exc:
        running, problem = None, str(exc)
    if args.json:
        print(json.dumps({"installed": installed, "config": configured, "running": running}))
    else:
        print("installed (entry points 'buddybot.apps'):")
        print("\n".join(f"  {n} = {t}" for n, t in sorted(installed.items())) or "  (none)")
        print(f"[apps] run ({ctx.config.source or 'no config file'}):")
        print("\n".join(f"  {s}" for s in configured) or "  (none)")
        print(f"running on robot {ctx.robot}:")
        if running is None:
            print("  ? (no router answered)")
        else:
            print("\n".join(f"  {n}" for n in running) or "  (none)")
    if problem:
        print(f"buddybot app list: running apps unknown: {problem}", file=sys.stderr)
    return 0


SUBVERBS = (
    SubVerb("run", "run an app until Ctrl-C (exit 1: it raised, 2: it cannot be loaded)",
            _add_run, _run, "FILE|MODULE|NAME"),
    SubVerb("new", "write NAME.py, an app that runs as generated", _add_new, _new, "NAME"),
    SubVerb("list", "installed apps, the config's [apps], and the apps running now",
            _add_list, _list),
)
