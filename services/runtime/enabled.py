"""Which services and apps a config runs, the one rule of `up`, `doctor` and the
dashboard (pure): docs/core.md, 'What a config runs'."""

from __future__ import annotations

from collections.abc import Iterable

from buddybot.runtime import registry
from buddybot.runtime.config import ConfigBase

SIMULATED_SENSORS = ("radar-bridge", "camera")
"""The services that read the simulated world when they have no hardware."""


def simulated(name: str, config: ConfigBase, sim: bool) -> bool:
    """Whether sensor `name` is simulated: asked (`sim`, its table's) or no hardware."""
    if name == "radar-bridge":
        return bool(sim or config.radar_bridge.sim or not config.radar_bridge.sensors)
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
