"""Which angle-radar targets count for presence: the zones rule (pure).

A target is judged by its position in the camera's frame (x forward, y
left: `RadarTarget.position`), against `[radar_presence] zones`
(`RadarZone` rectangles, validated in settings.py):

* inside any `ignore` zone: never counts, even inside a detect zone (a TV
  standing in the living room's detect zone stays ignored);
* else, when at least one `detect` zone exists: counts only inside one;
* no detect zone: counts (zones off = every target counts).

Edges belong to the zone (closed rectangles), like the sensor's own zone
filter. Rectangles, not polygons: they are what the LD2450's filter
takes, so a zone drawn for one can be copied to the other, and a room's
doorway or couch is a rectangle to within the sensor's accuracy.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence

from buddybot.radar.settings import RadarZone


class ZoneVerdict(enum.Enum):
    COUNTED = "counted"
    IGNORED = "ignored"
    """Inside an ignore zone."""
    OUTSIDE = "outside"
    """Outside every detect zone."""


def contains(zone: RadarZone, x: float, y: float) -> bool:
    """Whether (x, y) lies in the zone, edges included."""
    return zone.x[0] <= x <= zone.x[1] and zone.y[0] <= y <= zone.y[1]


def judge(zones: Sequence[RadarZone], x: float, y: float) -> ZoneVerdict:
    """What the zones say about a target at (x, y) in the camera's frame."""
    if any(zone.mode == "ignore" and contains(zone, x, y) for zone in zones):
        return ZoneVerdict.IGNORED
    detect = [zone for zone in zones if zone.mode == "detect"]
    if detect and not any(contains(zone, x, y) for zone in detect):
        return ZoneVerdict.OUTSIDE
    return ZoneVerdict.COUNTED
