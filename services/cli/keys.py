"""`buddybot keys`: the key catalogue (what `echo`, `pub` and `call` accept)."""

from __future__ import annotations

import argparse

from buddybot.core import keys
from buddybot.core.service import ServiceContext

HELP = "list the key catalogue"
USES_CONFIG = False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No options of its own."""


def main(ctx: ServiceContext) -> int:
    for row in keys.key_table():
        kind = row["kind"]
        what = row.get("type") or (f"{row.get('request')} -> {row.get('reply')}"
                                   if kind == "service" else "")
        latched = " latched" if row.get("latched") else ""
        print(f"{row['key']:<28} {kind:<10} {what}{latched}")
    return 0
