"""Hall's proxemic zones of a distance, with hysteresis.

`zone_of` is the plain zone of a distance. `zone_after` is the zone a person
moves to from `current`: every limit crossed must be passed by
`zone_margin_m`, outwards and inwards alike, so a person standing on a limit
(a face distance that wobbles by a few centimetres) stays in one zone, and a
change always lands in the zone the distance is in.
"""

from __future__ import annotations

import enum

from buddybot.people.settings import PeopleSettings


class Zone(enum.IntEnum):
    """Ordered from near to far, so `<` means nearer."""

    INTIMATE = 0
    PERSONAL = 1
    SOCIAL = 2
    PUBLIC = 3


def zone_of(distance_m: float, settings: PeopleSettings) -> Zone:
    """The zone a distance lies in; a limit belongs to the farther zone."""
    if distance_m < settings.intimate_limit_m:
        return Zone.INTIMATE
    if distance_m < settings.personal_limit_m:
        return Zone.PERSONAL
    if distance_m < settings.social_limit_m:
        return Zone.SOCIAL
    return Zone.PUBLIC


def zone_after(current: Zone, distance_m: float, settings: PeopleSettings) -> Zone:
    """The zone after a new distance: `current` unless the distance lies past one
    of its limits by the margin, then the zone the distance lies in with every
    limit crossed passed by the margin."""
    farther = zone_of(distance_m - settings.zone_margin_m, settings)
    if farther > current:
        return farther
    nearer = zone_of(distance_m + settings.zone_margin_m, settings)
    if nearer < current:
        return nearer
    return current
