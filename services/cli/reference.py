"""`buddybot reference`: write (or `--check`) the generated pages of docs/reference/."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from buddybot.runtime import registry
from buddybot.runtime.service import ServiceContext, add_common_arguments
from buddybot.tools import reference

HELP = "write (or --check) the reference pages in docs/reference/"
USES_CONFIG = False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=str(reference.OUT),
                        help="folder (default: docs/reference)")
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if a page is out of date")


def extensions() -> list[tuple[str, argparse.ArgumentParser]]:
    """The parsers of `buddybot run SERVICE` and of the tool verbs, as `main` builds them."""
    found = []
    for prefix, entries in (("buddybot run ", registry.SERVICES), ("buddybot ", registry.TOOLS)):
        for entry in entries:
            if not entry.exists():
                continue
            prog = prefix + entry.name
            parser = argparse.ArgumentParser(prog=prog, description=entry.help)
            add_common_arguments(parser)
            entry.load().add_arguments(parser)
            found.append((prog, parser))
    return found


def main(ctx: ServiceContext) -> int:
    from buddybot.cli import build_parser

    out = Path(ctx.args.out)
    files = reference.generate(build_parser(), extensions())
    if ctx.args.check:
        stale = reference.drift(out, files)
        for name in stale:
            print(f"out of date: {out / name} (run `buddybot reference`)", file=sys.stderr)
        return 1 if stale else 0
    for path in reference.write(out, files):
        print(path)
    return 0
