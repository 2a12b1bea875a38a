"""`buddybot schemas`: write (or `--check`) the JSON Schemas in `schemas/`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from buddybot.contract import schemas
from buddybot.runtime.service import ServiceContext

HELP = "write (or --check) the JSON schemas in schemas/"
USES_CONFIG = False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="schemas", help="folder (default: schemas)")
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if the folder is out of date")


def main(ctx: ServiceContext) -> int:
    out = Path(ctx.args.out)
    if ctx.args.check:
        stale = schemas.drift(out)
        for name in stale:
            print(f"out of date: {out / name}", file=sys.stderr)
        return 1 if stale else 0
    for path in schemas.write(out):
        print(path)
    return 0
