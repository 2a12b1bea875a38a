"""Hall's zones of a distance, and the hysteresis of a move between them."""

from __future__ import annotations

import pytest

from buddybot.people.settings import PeopleSettings
from buddybot.people.zones import Zone, zone_after, zone_of

S = PeopleSettings(intimate_limit_m=0.45, personal_limit_m=1.2, social_limit_m=3.6,
                   zone_margin_m=0.1)
I, P, SO, PU = Zone.INTIMATE, Zone.PERSONAL, Zone.SOCIAL, Zone.PUBLIC


@pytest.mark.parametrize(("distance_m", "zone"), [
    (0.0, I), (0.44, I), (0.45, P), (1.19, P), (1.2, SO), (3.59, SO), (3.6, PU), (50.0, PU)])
def test_zone_of(distance_m: float, zone: Zone) -> None:
    assert zone_of(distance_m, S) is zone


@pytest.mark.parametrize(("current", "distance_m", "zone"), [
    (P, 1.25, P),   # past the limit, not by the margin
    (P, 1.3, SO),   # by the margin
    (SO, 1.15, SO),
    (SO, 1.09, P),
    (I, 0.5, I),
    (I, 0.55, P),
    (P, 0.36, P),
    (P, 0.34, I),
    (SO, 3.65, SO),
    (SO, 3.7, PU),
    (PU, 3.55, PU),
    (PU, 3.49, SO),
    (I, 3.65, SO),  # a jump: every limit crossed needs the margin, the last one too
    (I, 3.7, PU),
    (PU, 0.3, I),
    (PU, 0.4, P),
    (SO, 2.0, SO),
])
def test_zone_after(current: Zone, distance_m: float, zone: Zone) -> None:
    assert zone_after(current, distance_m, S) is zone


def test_without_a_margin_the_zone_is_the_distances() -> None:
    s = PeopleSettings(zone_margin_m=0.0)
    for current in Zone:
        for d in (0.0, 0.44, 0.45, 1.19, 1.2, 3.59, 3.6, 9.0):
            assert zone_after(current, d, s) is zone_of(d, s)
