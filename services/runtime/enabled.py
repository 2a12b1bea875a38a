"""Which services and apps a config runs: the one rule `up` starts by, `doctor`
expects by and the dashboard keeps listing by.

`up` starts every installed service that is not on request, the on-request
ones whose table says `enabled = true` (foxglove, identity, ros2-bridge),
the simulated world only when a sensor is simulated, and the apps of
`[apps] run`. Doctor must expect exactly that, or it reports as "missing" a
service the robot was never meant to run. Pure: config and registry in,
names out.
"""

from __future__ import annotations

from collections.abc import Iterable

from buddybot.runtime import registry
from buddybot.runtime.config import ConfigBase

SIMULATED_SENSORS = ("radar-bridge", "camera")
"""The services that read the simulated world when they have no hardware."""


def simulated(name: str, config: ConfigBase, sim: bool) -> bool:
    """Whether sensor service `name` runs on the simulated world: asked (`sim`, the
    table's `sim`) or no hardware configured."""
    if name == "radar-bridge":
        table = config.radar_bridge
        return bool(sim or table.sim or not table.sensors)
    if name == "camera":
        return bool(sim or config.camera.sim or not config.camera.source)
    return False


def table_enables(entry: registry.Entry, config: ConfigBase) -> bool:
    """Whether an on-request service's table says `enabled = true`."""
    table = getattr(config, entry.table, None) if entry.table else None
    return bool(getattr(table, "enabled", False))


def enabled_services(config: ConfigBase, installed: Iterable[registry.Entry], *,
                     sim: bool = False) -> list[registry.Entry]:
    """The installed services `up` (without options but `--sim`) runs for `config`."""
    chosen = [e for e in installed if not e.on_request or table_enables(e, config)]
    names = {e.name for e in chosen}
    if not any(simulated(n, config, sim) for n in SIMULATED_SENSORS if n in names):
        chosen = [e for e in chosen if not e.simulation]
    return chosen


def app_names(config: ConfigBase) -> list[str]:
    """The node names of the apps of `[apps] run`."""
    return [spec.default_name for spec in config.apps.specs()]


def node_names(config: ConfigBase, installed: Iterable[registry.Entry], *,
               sim: bool = False) -> frozenset[str]:
    """Every node the config runs: its enabled services and its apps."""
    return frozenset([e.name for e in enabled_services(config, installed, sim=sim)]
                     + app_names(config))
