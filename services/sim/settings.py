"""Config table `[sim]`: which simulated world every simulated sensor renders (pure)."""

from __future__ import annotations

from typing import Annotated

import msgspec


class SimSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    scenario: Annotated[str, msgspec.Meta(
        min_length=1, max_length=4096,
        description="the simulated world: a built-in scenario (`buddybot sim list`) or "
        "a scenario file")] = "visit"
    seed: Annotated[int, msgspec.Meta(
        ge=0, le=2**31 - 1,
        description="makes the world's small random motions repeatable")] = 0
    speed: Annotated[float, msgspec.Meta(
        gt=0.0, le=100.0,
        description="scenario time per wall-clock second (2 runs a scenario twice as "
        "fast)")] = 1.0
    start: Annotated[float, msgspec.Meta(
        ge=0.0, le=1e11,
        description="wall-clock time (Unix seconds) at which the scenario starts; 0: when "
        "the process starts (`up` gives all its simulated sensors one start)")] = 0.0
    rate_hz: Annotated[float, msgspec.Meta(
        gt=0.0, le=50.0,
        description="how often the sim service publishes the world's truth on "
        "sim/world")] = 10.0
