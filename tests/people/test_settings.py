"""`PeopleSettings`: defaults, ranges and the order of the zone limits."""

from __future__ import annotations

from typing import Any

import msgspec
import pytest

from buddybot.people.settings import PeopleSettings


def test_the_defaults_are_halls_limits() -> None:
    s = msgspec.convert({}, PeopleSettings)
    assert (s.intimate_limit_m, s.personal_limit_m, s.social_limit_m) == (0.45, 1.2, 3.6)
    assert 0.0 < s.zone_margin_m < s.intimate_limit_m


@pytest.mark.parametrize("fields", [
    {"intimate_limit_m": 1.2, "personal_limit_m": 1.2},
    {"personal_limit_m": 4.0},
    {"social_limit_m": 1.0},
])
def test_zone_limits_must_grow(fields: dict[str, Any]) -> None:
    with pytest.raises(msgspec.ValidationError, match="zone limits must grow"):
        msgspec.convert(fields, PeopleSettings)


@pytest.mark.parametrize("fields", [
    {"face_timeout_s": 0.0},
    {"engage_dwell_s": -0.1},
    {"absence_hold_s": 3601.0},
    {"zone_margin_m": -0.01},
    {"intimate_limit_m": 0.0},
    {"position_period_s": -0.1},
    {"position_period_s": 1.5},
    {"position_period_s": "fast"},
    {"walking_speed": 1.0},
])
def test_out_of_range_and_unknown_fields_are_refused(fields: dict[str, Any]) -> None:
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert(fields, PeopleSettings)
