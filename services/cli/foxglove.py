"""`buddybot foxglove`: the Foxglove bridge in the foreground (docs/foxglove.md).

The same service as `buddybot run foxglove` (and `buddybot up --foxglove`),
under a shorter name for the common case: open the robot in the Foxglove app.
"""

from __future__ import annotations

import argparse

from buddybot.foxglove import options
from buddybot.runtime.service import ServiceContext

HELP = "serve every key live to the Foxglove app (ws://127.0.0.1:8765)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_arguments(parser)


def main(ctx: ServiceContext) -> int:
    from buddybot.foxglove import service  # the SDK is imported only when the bridge runs

    return service.run(ctx)
