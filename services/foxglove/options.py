"""The bridge's command-line options and merged settings, without the SDK.

Kept apart from `service.py` so `buddybot --help` (which builds every
verb's parser, `buddybot foxglove` included) does not import `foxglove`.
"""

from __future__ import annotations

import argparse

from buddybot.foxglove.settings import FoxgloveSettings
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.service import ServiceContext


def add_arguments(parser: argparse.ArgumentParser) -> None:
    settings_option(parser, "--port", struct=FoxgloveSettings, field="port")
    settings_option(parser, "--host", struct=FoxgloveSettings, field="host")
    settings_option(parser, "--max-image-fps", struct=FoxgloveSettings, field="max_image_fps")
    settings_option(parser, "--login", struct=FoxgloveSettings, field="login")


def settings_from(ctx: ServiceContext) -> FoxgloveSettings:
    """`[foxglove]` with the command line on top."""
    return merge(ctx.config.section(FoxgloveSettings), ctx.args)
