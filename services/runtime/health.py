"""What `buddybot doctor` asks of a service: its checks, in one shape for all.

Doctor knows the generic checks (config, router, nodes, clock...); what is
particular to a service (a radar's serial ports, a camera that opens, an audio
device, the packages it needs, the rate of its stream) lives in its area and
reaches doctor through the registry (`Entry.doctor`), so doctor imports no
area and an area no tool.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

Level = Literal["OK", "WARN", "FAIL"]
OK: Level = "OK"
WARN: Level = "WARN"
FAIL: Level = "FAIL"


@dataclass(frozen=True)
class Check:
    """One verdict: `name` says what was checked, `detail` what was found."""

    name: str
    level: Level
    detail: str

    @property
    def failed(self) -> bool:
        return self.level == FAIL


@dataclass(frozen=True)
class Rate:
    """A stream doctor counts on the bus: its shown name, its key below the
    robot's prefix (wildcards allowed) and the rate it should have."""

    name: str
    key: str
    hz: float
    also: tuple[str, ...] = ()
    """More keys counted under the name (a sensor whose model is not configured)."""


DeviceChecks = Callable[[Any, bool, bool], list[Check]]
"""(the service's settings, simulated, held by the running service) -> its device
checks. `simulated` is `--sim`; the settings may say so as well."""


@dataclass(frozen=True)
class DoctorHooks:
    """A service's part of doctor (every part optional)."""

    devices: DeviceChecks | None = None
    """The quick checks of its devices (no running robot needed)."""
    packages: tuple[tuple[str, tuple[str, ...]], ...] = ()
    """(shown name, distribution names to try) of what it runs on, for the versions line."""
    rates: Callable[[Any, bool], list[Rate]] | None = None
    """(settings, simulated) -> the streams it publishes (by its model) and rates."""
