"""Config tables `[radar_bridge]` and `[radar_presence]` (pure msgspec structs)."""

from __future__ import annotations

import msgspec


class RadarBridgeSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Sensors are pyserial URLs; `radar_id` is their index in this list."""

    sensors: list[str] = msgspec.field(default_factory=list)
    device_id: int = 0
    baudrate: int = 256000
    sim: bool = False


class RadarPresenceSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    range_m: float = 2.0
