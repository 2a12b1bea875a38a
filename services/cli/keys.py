"""`buddybot keys`: the key catalogue (what `echo`, `pub` and `call` accept)."""

from __future__ import annotations

import argparse
import json

from buddybot.contract import keys
from buddybot.runtime import options
from buddybot.runtime.service import ServiceContext

HELP = "list the key catalogue"
USES_CONFIG = False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_json_argument(parser, "one JSON document (the rows of schemas/keys.json)")


def main(ctx: ServiceContext) -> int:
    if ctx.args.json:
        print(json.dumps(keys.key_table()))
        return 0
    for row in keys.key_table():
        kind = row["kind"]
        what = row.get("type") or (f"{row.get('request')} -> {row.get('reply')}"
                                   if kind == "service" else "")
        latched = " latched" if row.get("latched") else ""
        print(f"{row['key']:<28} {kind:<10} {what}{latched}")
    return 0
