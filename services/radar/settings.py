"""Config tables `[radar_bridge]` and `[radar_presence]` (pure msgspec structs).

Every default is chosen for a real LD2410 at its factory settings; the
reasons are in docs/radar.md. Each number carries its range and a
description (unit, why): the config file, the command-line options
(`buddybot.runtime.overrides`) and their help all take them from here.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

ZONE_LIMIT_M = 20.0
"""Farthest zone edge from the camera, metres: the LD2450 sees to 8 m and a
mounting offset adds little; a zone beyond 20 m is a typo (mm for m)."""
ZONE_MIN_SIDE_M = 0.1
"""Narrowest zone side, metres: a person is ~0.4 m across and a target's
position jitters by about 0.1 m, so a narrower zone holds someone only by chance."""
MAX_ZONES = 16
"""Zones at most: a room needs a few (the sensor's own filter has 3)."""

ZoneEdge = Annotated[float, msgspec.Meta(ge=-ZONE_LIMIT_M, le=ZONE_LIMIT_M)]
ZoneSpan = Annotated[list[ZoneEdge], msgspec.Meta(min_length=2, max_length=2)]


class RadarZone(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """A rectangle of floor in the camera's frame (metres, x forward, y left, as
    `RadarTarget.position`): `detect` (only targets inside one count) or
    `ignore` (targets inside never count: a doorway, a TV). Edges are inside.
    Checked when the config or a `param set` is read; the rule is in zones.py."""

    name: Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
    mode: Literal["detect", "ignore"]
    x: ZoneSpan
    """[near, far]: metres forward of the camera."""
    y: ZoneSpan
    """[right, left]: metres to the camera's left (right is negative)."""

    def __post_init__(self) -> None:
        for axis, (low, high) in (("x", self.x), ("y", self.y)):
            span = f"zone {self.name!r}: {axis} = [{low}, {high}]"
            if low > high:
                raise ValueError(f"{span} is inverted: write [{high}, {low}] (smaller first)")
            if high - low < ZONE_MIN_SIDE_M:
                raise ValueError(f"{span} is {'empty' if low == high else 'too narrow'}: "
                                 f"a side needs at least {ZONE_MIN_SIDE_M} m")


class RadarMount(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[[radar_bridge.mount]]`: where one angle radar sits relative to the camera
    (ROS axes: x forward, y left, z up). A sensor without an entry is at the
    camera, facing forward. See buddybot.radar.mounting."""

    sensor: Annotated[int, msgspec.Meta(
        ge=0, le=1023, description="the sensor's index in `sensors` (its radar_id)")]
    x: Annotated[float, msgspec.Meta(
        ge=-10.0, le=10.0, description="m, forward of the camera")] = 0.0
    y: Annotated[float, msgspec.Meta(
        ge=-10.0, le=10.0, description="m, to the camera's left")] = 0.0
    z: Annotated[float, msgspec.Meta(
        ge=-10.0, le=10.0, description="m, above the camera")] = 0.0
    yaw: Annotated[float, msgspec.Meta(
        ge=-3.1416, le=3.1416,
        description="rad, where the sensor faces: + = turned toward the robot's left")] = 0.0
    mirror_x: Annotated[bool, msgspec.Meta(
        description="the sensor's x axis points the other way (module mounted upside "
        "down)")] = False


class RadarBridgeSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Sensors are pyserial URLs; `radar_id` is their index in this list."""

    sensors: Annotated[list[Annotated[str, msgspec.Meta(min_length=1)]], msgspec.Meta(
        description="pyserial URLs of the sensors; radar_id = order")] = msgspec.field(
        default_factory=list)
    device_id: Annotated[int, msgspec.Meta(
        ge=0, le=65535,
        description="device id in the keys (radar/<device_id>/...): tells several "
        "bridges apart")] = 0
    baudrate: Annotated[int, msgspec.Meta(
        ge=1200, le=4_000_000,
        description="serial speed in bit/s; 256000 is the LD2410 factory default, "
        "a pty or socket:// URL ignores it")] = 256000
    models: Annotated[dict[str, str], msgspec.Meta(
        description="per sensor index, its model when it must not be recognised from "
        "its frames: \"LD2410\" or \"LD2450\" (e.g. {1 = \"LD2450\"}); the others are "
        "recognised at connect")] = msgspec.field(default_factory=dict)
    mount: Annotated[list[RadarMount], msgspec.Meta(
        description="[[radar_bridge.mount]] entries: each angle radar's pose relative "
        "to the camera (default: at the camera, facing forward)",
        examples=[[{"sensor": 1, "x": 0.0, "y": 0.05, "z": -0.1, "yaw": 0.35,
                    "mirror_x": False}]])] = msgspec.field(
        default_factory=list)
    sim: Annotated[bool, msgspec.Meta(
        description="add a simulated sensor on a pseudo-terminal, seeing the simulated "
        "world of [sim] (configured sensors are then left alone unless given with "
        "--sensor)")] = False
    sim_model: Annotated[str, msgspec.Meta(
        description="the simulated sensor's model: \"LD2410\" or \"LD2450\"")] = "LD2410"
    reconnect_initial_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0,
        description="seconds before the first reopen of a failed port; doubles up to "
        "reconnect_max_s")] = 0.5
    reconnect_max_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0,
        description="longest wait between reopen attempts, seconds")] = 5.0
    silence_timeout_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0,
        description="seconds without an intact frame before the port is reopened "
        "(the sensor sends ~10 frames/s)")] = 3.0
    query_firmware: Annotated[bool, msgspec.Meta(
        description="ask each sensor's firmware version at connect: only V2.x reports "
        "carry light level and OUT pin; off for a link that cannot send to the "
        "sensor")] = True


class RadarPresenceSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`extra={"live": True}`: `buddybot param set` applies it at once (the tracker
    reads its rules on every frame and tick); `max_sensors` sizes tables at start."""

    range_m: Annotated[float, msgspec.Meta(
        extra={"live": True},
        gt=0.0, le=10.0,
        description="metres: IN_RANGE when a target is this close (the LD2410 sees "
        "to ~6 m)")] = 2.0
    exit_margin_m: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=10.0,
        description="metres beyond range_m every target must be to leave (LD2410 "
        "jitter is ~0.2 m)")] = 0.3
    absence_hold_s: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=3600.0,
        description="seconds nobody is within the exit range before OUT_OF_RANGE "
        "(NO_TARGET blips)")] = 3.0
    target_hold_s: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=3600.0,
        description="seconds a new MOVING/STANDING kind must last before it is "
        "published")] = 1.0
    stale_after_s: Annotated[float, msgspec.Meta(
        extra={"live": True},
        gt=0.0, le=3600.0,
        description="seconds of silence before a sensor is excluded and reported "
        "(frames come every ~0.1 s)")] = 1.5
    max_sensors: Annotated[int, msgspec.Meta(
        ge=1, le=1024,
        description="sensors remembered at most, least recently heard forgotten "
        "first: a robot has a few; the bound keeps a flood of invented sensor ids "
        "from growing the table")] = 16
    moving_speed_mps: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=10.0,
        description="m/s: an angle-radar target faster than this is MOVING, else "
        "STANDING (a still person reads 0 to a few cm/s, a slow walk ~0.5 m/s)")] = 0.1
    zones: Annotated[list[RadarZone], msgspec.Meta(
        extra={"live": True}, max_length=MAX_ZONES,
        examples=[[{"name": "doorway", "mode": "ignore", "x": [2.0, 3.0], "y": [-1.0, 0.0]}]],
        description="rectangles in the camera's frame deciding which angle-radar "
        "targets count: detect (if any, a target must be inside one) or ignore "
        "(never counts); LD2410 readings have no position and ignore them")] = (
        msgspec.field(default_factory=list))

    def __post_init__(self) -> None:
        names = [zone.name for zone in self.zones]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"zones: each zone needs its own name; repeated: "
                             f"{', '.join(repr(n) for n in twice)}")
