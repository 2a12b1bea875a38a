"""The `[sim]` options every simulated sensor takes, and the world they describe.

Radar bridge, camera and the sim service all take `--scenario`, `--seed`,
`--sim-speed` and `--sim-start` (each overriding its `[sim]` key) and make
the same `World` and `SimClock` from them: that is how they agree.
"""

from __future__ import annotations

import argparse

from buddybot.runtime.errors import ConfigError
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.service import ServiceContext
from buddybot.sim.clock import SimClock
from buddybot.sim.scenario import ScenarioError, load
from buddybot.sim.settings import SimSettings
from buddybot.sim.world import World


def add_world_arguments(parser: argparse.ArgumentParser) -> None:
    settings_option(parser, "--scenario", struct=SimSettings, field="scenario",
                    metavar="NAME|FILE")
    settings_option(parser, "--seed", struct=SimSettings, field="seed")
    settings_option(parser, "--sim-speed", struct=SimSettings, field="speed")
    settings_option(parser, "--sim-start", struct=SimSettings, field="start",
                    metavar="UNIX_S")


def world_from(ctx: ServiceContext) -> tuple[World, SimClock, SimSettings]:
    """`[sim]` with the command line on top, loaded: ConfigError when it cannot run."""
    return world_of(merge(ctx.config.section(SimSettings), ctx.args))


def world_of(settings: SimSettings) -> tuple[World, SimClock, SimSettings]:
    """The world and clock of settings (ConfigError naming the scenario's key and line)."""
    try:
        scenario = load(settings.scenario)
    except ScenarioError as exc:
        raise ConfigError(str(exc)) from None
    return World(scenario, settings.seed), SimClock(settings.start, settings.speed), settings
