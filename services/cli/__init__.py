# PYTHON_ARGCOMPLETE_OK (argcomplete's marker: this command answers tab completion)
"""The `buddybot` command: the verbs robot people know from `ros2`.

    buddybot up [--sim] [--no-browser]     the whole robot on this machine
    buddybot router [--listen ENDPOINT]     a Zenoh router
    buddybot run SERVICE [options]          one service
    buddybot echo|hz|pub|call KEY ...       probe the robot
    buddybot nodes | keys | config          what runs, what exists, what is set
    buddybot topics | node info NAME        keys seen and their rates; one node
    buddybot param list|get|set|dump|load   live parameters of a node
    buddybot lease list|break [ID]          who holds the eyes and the speaker
    buddybot people enrol|list|forget       known faces, with consent
    buddybot bag record|play|info FILE      record keys to MCAP, replay, describe
    buddybot doctor [--quick]               is the robot healthy?
    buddybot schemas [--check]              regenerate / check schemas/
    buddybot reference [--check]            regenerate / check docs/reference/
    buddybot radar ...                      LD2410 configuration tools
    buddybot foxglove [--port P]            every key live in the Foxglove app
    buddybot app run|new|list               apps: run one, start one, list them
    buddybot secret show|rotate|revoke      the dashboard/Foxglove login secrets
    buddybot sim list|check                 the simulated world's scenarios

Exit status: 0 success, 1 failure at run time, 2 bad usage or config.
"""

from __future__ import annotations

# Each verb is a small module of this package (the ros2cli pattern): `HELP`,
# `add_arguments(parser)` and `main(ctx) -> int`, optionally `USES_CONFIG =
# False` for verbs that never read the robot's configuration. `run SERVICE`
# and the registry's tools bring their own parser (`buddybot run camera
# --help` lists the camera's options). Every path ends in one place,
# `buddybot.runtime.service.run_main`, which maps errors to exit statuses.
#
# Only what the command line names is imported: `buddybot run SERVICE` and
# `buddybot router` build that one verb's parser, so a service starts without
# loading every verb (the bag's MCAP reader, the sdk, the web login, ...).
import argparse
import contextlib
import importlib
import logging
import os
import sys
from collections.abc import Collection, Sequence
from types import ModuleType
from typing import Any, NoReturn

from buddybot import __version__
from buddybot.runtime import registry
from buddybot.runtime.errors import EXIT_USAGE

VERBS = ("up", "router", "echo", "hz", "pub", "call", "nodes", "keys", "config", "schemas",
         "reference",
         "doctor", "param", "lease", "people", "topics", "node", "foxglove", "bag", "app",
         "secret", "sim")
"""Verb modules of this package, in the order `buddybot --help` lists them."""


def verb_module(name: str) -> ModuleType:
    return importlib.import_module(f"{__name__}.{name}")


def version_line() -> str:
    """`buddybot --version`: also the Python and Zenoh versions, the two a bug
    report needs first (read from package metadata: nothing is imported)."""
    import importlib.metadata  # slow to load: only when the version is asked for
    import platform

    try:
        zenoh = importlib.metadata.version("eclipse-zenoh")
    except importlib.metadata.PackageNotFoundError:
        zenoh = "not installed"
    return f"buddybot {__version__} (Python {platform.python_version()}, eclipse-zenoh {zenoh})"


def complete() -> None:
    """Answer a shell's tab-completion request, if this run is one, and exit.

    argcomplete's protocol: the shell hook (`eval "$(register-python-argcomplete
    buddybot)"`) runs the command with `_ARGCOMPLETE` and `COMP_LINE` set.
    The parser is built and argcomplete imported only then, so ordinary runs
    (and the tools, which skip the parser) start no slower."""
    if "_ARGCOMPLETE" not in os.environ:
        return
    import argcomplete

    argcomplete.autocomplete(build_parser())


class _VersionAction(argparse._VersionAction):
    """argparse's `--version`, its line made only when asked for (`version_line`
    reads package metadata, too slow for every start of a service)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        self.version = version_line()
        super().__call__(parser, namespace, values, option_string)


def named_verbs(argv: Sequence[str]) -> Collection[str] | None:
    """The verbs whose parsers `argv` needs (`build_parser(verbs=...)`), None for all.

    A first word naming a verb needs that verb alone: argparse hands everything
    after it to that verb's parser. `--version` (or an abbreviation of it) first
    needs none: it prints and exits before any verb is looked at. Anything else
    (`--help`, no verb, an unknown one) shows the whole list, so builds it all."""
    first = argv[0] if argv else ""
    if first in VERBS or first == "run":
        return (first,)
    if len(first) > 2 and "--version".startswith(first):
        return ()
    return None


def build_parser(verbs: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The `buddybot` parser with every verb, or only `verbs` (their modules alone
    are imported; the command line must name one of them, see `named_verbs`)."""
    parser = argparse.ArgumentParser(
        prog="buddybot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--version", action=_VersionAction)
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    wanted = {*VERBS, "run", *(t.name for t in registry.TOOLS)} if verbs is None else {*verbs}
    for name in (n for n in VERBS if n in wanted):
        module = verb_module(name)
        sub = subparsers.add_parser(name, help=module.HELP, description=module.HELP)
        if getattr(module, "USES_CONFIG", True):
            from buddybot.runtime.service import add_common_arguments  # not for `--version`

            add_common_arguments(sub)
        module.add_arguments(sub)
        sub.set_defaults(module=module)

    if "run" in wanted:
        run = subparsers.add_parser(
            "run", help="run one service", description="Run one service as this process. "
            "`buddybot run SERVICE --help` lists its options.\n\nservices:\n" + "\n".join(
                f"  {e.name:<16}{e.help}" for e in registry.SERVICES),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        run.add_argument("service", choices=[e.name for e in registry.SERVICES],
                         metavar="SERVICE")
        run.add_argument("service_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)

    for tool in registry.TOOLS:  # their own parser sees everything, `--help` included
        if tool.name in wanted:
            sub = subparsers.add_parser(tool.name, help=tool.help, add_help=False)
            sub.add_argument("tool_args", nargs=argparse.REMAINDER)
    return parser


def _extension(entry: registry.Entry, prog: str, argv: list[str]) -> int:
    """Run a registered service or tool module: its own parser, the shared options."""
    if not entry.exists():
        print(f"{prog}: not installed", file=sys.stderr)
        return EXIT_USAGE
    from buddybot.runtime.service import add_common_arguments, run_main

    module = entry.load()
    parser = argparse.ArgumentParser(prog=prog, description=entry.help)
    add_common_arguments(parser)
    module.add_arguments(parser)
    return run_main(entry.name, parser.parse_args(argv), module.run)


def main(argv: Sequence[str] | None = None) -> int:
    complete()  # first: a completion request comes with no argv
    argv = list(sys.argv[1:] if argv is None else argv)
    tool = next((t for t in registry.TOOLS if argv and argv[0] == t.name), None)
    if tool is not None:
        return _extension(tool, f"buddybot {tool.name}", argv[1:])
    args = build_parser(named_verbs(argv)).parse_args(argv)
    if args.verb == "run":
        entry = registry.service(args.service)
        assert entry is not None  # argparse checked the choice
        return _extension(entry, f"buddybot run {entry.name}", args.service_args)
    from buddybot.runtime.service import run_main

    module = args.module
    return run_main(args.verb, args, module.main,
                    uses_config=getattr(module, "USES_CONFIG", True))


def run_and_exit() -> NoReturn:
    """The `buddybot` program: `main`, then out without interpreter finalization.

    A daemon thread still waiting inside Zenoh's native code (a receive, the
    replies of a query) would be ended there by finalization, and glibc aborts
    such a process ("exception not rethrown"). By the time `main` returns every
    node and file is closed, so logs and streams are flushed and the process
    exits at once with main's status.
    """
    try:
        status = main()
    except SystemExit as stop:  # argparse's --help and usage errors
        if isinstance(stop.code, str):
            print(stop.code, file=sys.stderr)
        status = stop.code if isinstance(stop.code, int) else int(stop.code is not None)
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


if __name__ == "__main__":
    run_and_exit()
