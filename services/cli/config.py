"""`buddybot config`: the effective configuration, as TOML that `--config` accepts."""

from __future__ import annotations

import argparse
import json
from typing import Any

from buddybot.runtime import options
from buddybot.runtime.config import to_toml_dict
from buddybot.runtime.service import ServiceContext

HELP = "print the effective configuration"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The common options (`--config`, `--robot`, `--connect`), and `--json`."""
    options.add_json_argument(parser, "one JSON document instead of TOML (unset keys are null)")


def main(ctx: ServiceContext) -> int:
    import tomli_w

    data = to_toml_dict(ctx.config)
    data["robot"]["id"] = ctx.robot  # type: ignore[index]
    data["zenoh"]["connect"] = ctx.connect  # type: ignore[index]
    if ctx.args.json:
        print(json.dumps(data, indent=2))
        return 0
    print(tomli_w.dumps(_drop_none(data)), end="")
    return 0


def _drop_none(value: Any) -> Any:
    """TOML has no null: an unset optional key is left out."""
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    return value
