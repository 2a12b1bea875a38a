"""Config tables `[radar_bridge]` and `[radar_presence]` (pure msgspec structs).

Every default is chosen for a real LD2410 at its factory settings; the
reasons are in docs/radar.md.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

Positive = Annotated[float, msgspec.Meta(gt=0.0)]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0)]


class RadarBridgeSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Sensors are pyserial URLs; `radar_id` is their index in this list."""

    sensors: list[str] = msgspec.field(default_factory=list)
    device_id: Annotated[int, msgspec.Meta(ge=0)] = 0
    # LD2410 factory default; a pty or socket:// URL ignores it.
    baudrate: Annotated[int, msgspec.Meta(gt=0)] = 256000
    sim: bool = False
    # Simulated sensor: scenario name (see buddybot.radar.scenarios.SCENARIOS) and time scale.
    sim_scenario: str = "visit"
    sim_speed: Positive = 1.0
    # Reconnect backoff: first retry after reconnect_initial_s, doubling up to reconnect_max_s.
    reconnect_initial_s: Positive = 0.5
    reconnect_max_s: Positive = 5.0
    # A port that delivers no intact frame for this long is reopened (the sensor sends ~10/s).
    silence_timeout_s: Positive = 3.0
    # Ask each sensor's firmware version at connect: only V2.x reports carry light
    # level and OUT pin. Off for a link that cannot send to the sensor.
    query_firmware: bool = True


class RadarPresenceSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    range_m: Positive = 2.0
    # Leaving needs every target beyond range_m + exit_margin_m (LD2410 jitter is ~0.2 m).
    exit_margin_m: NonNegative = 0.3
    # Nobody within the exit range for this long before OUT_OF_RANGE (NO_TARGET blips).
    absence_hold_s: NonNegative = 3.0
    # A new MOVING/STANDING kind must last this long before it is published.
    target_hold_s: NonNegative = 1.0
    # A sensor silent for this long is excluded and reported (frames come every ~0.1 s).
    stale_after_s: Positive = 1.5
    # Sensors remembered at most (least recently heard forgotten first): a robot has a
    # few; the bound keeps a flood of invented sensor ids from growing the table.
    max_sensors: Annotated[int, msgspec.Meta(ge=1, le=1024)] = 16
