"""Hall's zones of a distance, and the hysteresis of a move between them."""

from __future__ import annotations

import pytest

from buddybot.people.settings import PeopleSettings
from buddybot.people.zones import Zone, zone_after, zone_of

S = PeopleSettings(intimate_limit_m=0.45, personal_limit_m=1.2, social_limit_m=3.6,
                   zone_margin_m=0.1)
INT, PER, SOC, PUB = Zone.INTIMATE, Zone.PERSONAL, Zone.SOCIAL, Zone.PUBLIC


@pytest.mark.parametrize(("distance_m", "zone"), [
    (0.0, INT), (0.44, INT), (0.45, PER), (1.19, PER), (1.2, SOC), (3.59, SOC), (3.6, PUB),
    (50.0, PUB)])
def test_zone_of(distance_m: float, zone: Zone) -> None:
    assert zone_of(distance_m, S) is zone


@pytest.mark.parametrize(("current", "distance_m", "zone"), [
    (PER, 1.25, PER),  # past the limit, not by the margin
    (PER, 1.3, SOC),  # by the margin
    (SOC, 1.15, SOC),
    (SOC, 1.09, PER),
    (INT, 0.5, INT),
    (INT, 0.55, PER),
    (PER, 0.36, PER),
    (PER, 0.34, INT),
    (SOC, 3.65, SOC),
    (SOC, 3.7, PUB),
    (PUB, 3.55, PUB),
    (PUB, 3.49, SOC),
    (INT, 3.65, SOC),  # a jump: every limit crossed needs the margin, the last one too
    (INT, 3.7, PUB),
    (PUB, 0.3, INT),
    (PUB, 0.4, PER),
    (SOC, 2.0, SOC),
])
def test_zone_after(current: Zone, distance_m: float, zone: Zone) -> None:
    assert zone_after(current, distance_m, S) is zone


def test_without_a_margin_the_zone_is_the_distances() -> None:
    s = PeopleSettings(zone_margin_m=0.0)
    for current in Zone:
        for d in (0.0, 0.44, 0.45, 1.19, 1.2, 3.59, 3.6, 9.0):
            assert zone_after(current, d, s) is zone_of(d, s)
