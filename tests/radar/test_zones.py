"""Zones (pure): which angle-radar targets count, and what a zone may be."""

from __future__ import annotations

from typing import Any

import msgspec
import pytest

from buddybot.radar.settings import MAX_ZONES, RadarPresenceSettings, RadarZone
from buddybot.radar.zones import ZoneVerdict, contains, judge
from buddybot.runtime.config import parse_config
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.params import ParamRefused, validate

COUNTED, IGNORED, OUTSIDE = ZoneVerdict.COUNTED, ZoneVerdict.IGNORED, ZoneVerdict.OUTSIDE


def zone(name: str, mode: str, x: list[float], y: list[float]) -> RadarZone:
    return msgspec.convert({"name": name, "mode": mode, "x": x, "y": y}, RadarZone)


ROOM = zone("room", "detect", [0.5, 4.0], [-2.0, 2.0])
DOOR = zone("doorway", "ignore", [2.0, 3.0], [-1.0, 0.0])
SOFA = zone("sofa", "detect", [1.0, 2.0], [2.5, 3.5])


def test_no_zones_every_target_counts() -> None:
    assert judge([], 1.0, 0.0) == COUNTED
    assert judge([], 7.9, -3.9) == COUNTED


def test_only_ignore_zones_count_everything_outside_them() -> None:
    assert judge([DOOR], 2.5, -0.5) == IGNORED
    assert judge([DOOR], 1.0, -0.5) == COUNTED
    assert judge([DOOR], 2.5, 0.5) == COUNTED


def test_with_a_detect_zone_a_target_must_be_inside_one() -> None:
    assert judge([ROOM, SOFA], 1.0, 0.0) == COUNTED
    assert judge([ROOM, SOFA], 1.5, 3.0) == COUNTED  # in the second detect zone
    assert judge([ROOM, SOFA], 5.0, 0.0) == OUTSIDE
    assert judge([ROOM, SOFA], 0.2, 0.0) == OUTSIDE
    assert judge([ROOM, SOFA], 1.0, 2.2) == OUTSIDE  # between the two


def test_ignore_wins_over_detect() -> None:
    """A doorway inside the room's detect zone stays ignored."""
    assert judge([ROOM, DOOR], 2.5, -0.5) == IGNORED
    assert judge([DOOR, ROOM], 2.5, -0.5) == IGNORED  # order does not matter
    assert judge([ROOM, DOOR], 1.5, -0.5) == COUNTED


@pytest.mark.parametrize(("x", "y"), [(2.0, -1.0), (3.0, 0.0), (2.0, 0.0), (3.0, -1.0),
                                      (2.5, -1.0), (2.0, -0.5)])
def test_edges_and_corners_are_inside(x: float, y: float) -> None:
    assert contains(DOOR, x, y)
    assert judge([DOOR], x, y) == IGNORED


@pytest.mark.parametrize(("x", "y"), [(1.999, -0.5), (3.001, -0.5), (2.5, -1.001), (2.5, 0.001)])
def test_just_outside_an_edge_is_outside(x: float, y: float) -> None:
    assert not contains(DOOR, x, y)
    assert judge([DOOR], x, y) == COUNTED


def test_y_is_left_positive_as_the_camera_frame() -> None:
    """The doorway spans y -1..0: on the robot's right, not its left."""
    assert judge([DOOR], 2.5, -0.5) == IGNORED
    assert judge([DOOR], 2.5, 0.5) == COUNTED


@pytest.mark.parametrize(("fields", "message"), [
    ({"x": [3.0, 2.0]}, r"zone 'z': x = \[3.0, 2.0\] is inverted: write \[2.0, 3.0\]"),
    ({"y": [1.0, -1.0]}, r"zone 'z': y = \[1.0, -1.0\] is inverted"),
    ({"x": [2.0, 2.0]}, r"zone 'z': x = \[2.0, 2.0\] is empty: a side needs at least 0.1 m"),
    ({"y": [0.0, 0.05]}, r"y = \[0.0, 0.05\] is too narrow"),
    ({"x": [2.0, 3000.0]}, r"Expected `float` <= 20.0 - at `\$.x\[1\]`"),
    ({"y": [-25.0, 0.0]}, r">= -20.0 - at `\$.y\[0\]`"),
    ({"x": [float("nan"), 1.0]}, r"at `\$.x\[0\]`"),
    ({"x": [1.0]}, r"length >= 2 - at `\$.x`"),
    ({"x": [1.0, 2.0, 3.0]}, r"length <= 2 - at `\$.x`"),
    ({"mode": "watch"}, r"Invalid enum value 'watch' - at `\$.mode`"),
    ({"name": ""}, r"length >= 1 - at `\$.name`"),
    ({"height": [0, 1]}, r"unknown field `height`"),
])
def test_a_bad_zone_is_refused_with_what_is_wrong(fields: dict[str, Any], message: str) -> None:
    raw = {"name": "z", "mode": "detect", "x": [1.0, 2.0], "y": [-1.0, 1.0], **fields}
    with pytest.raises(msgspec.ValidationError, match=message):
        msgspec.convert(raw, RadarZone)


def test_the_narrowest_zone_allowed() -> None:
    assert zone("strip", "ignore", [1.0, 1.1], [0.0, 0.1]).x == [1.0, 1.1]


@pytest.mark.parametrize("missing", ["name", "mode", "x", "y"])
def test_every_zone_field_is_required(missing: str) -> None:
    """No default mode: a zone whose mode was forgotten must not silently be a
    detect zone that makes every other target vanish."""
    raw = {"name": "z", "mode": "detect", "x": [1.0, 2.0], "y": [-1.0, 1.0]}
    del raw[missing]
    with pytest.raises(msgspec.ValidationError, match=f"missing required field `{missing}`"):
        msgspec.convert(raw, RadarZone)


def test_zone_names_are_unique_and_zones_bounded() -> None:
    two = [msgspec.to_builtins(DOOR), {**msgspec.to_builtins(ROOM), "name": "doorway"}]
    with pytest.raises(msgspec.ValidationError, match="repeated: 'doorway'"):
        msgspec.convert({"zones": two}, RadarPresenceSettings)
    many = [{**msgspec.to_builtins(ROOM), "name": f"z{i}"} for i in range(MAX_ZONES + 1)]
    with pytest.raises(msgspec.ValidationError, match=f"length <= {MAX_ZONES}"):
        msgspec.convert({"zones": many}, RadarPresenceSettings)


def test_zones_from_the_config_file_and_its_errors() -> None:
    config = parse_config('[radar_presence]\nzones = [{name = "doorway", mode = "ignore", '
                          'x = [2.0, 3.0], y = [-1.0, 0.0]}]\n', "robot.toml")
    assert config.section(RadarPresenceSettings).zones == [DOOR]
    with pytest.raises(ConfigError, match=r"robot.toml: key 'radar_presence.zones\[0\]': "
                                          r"zone 'doorway': x = \[3.0, 2.0\] is inverted"):
        parse_config('[radar_presence]\nzones = [{name = "doorway", mode = "ignore", '
                     'x = [3.0, 2.0], y = [-1.0, 0.0]}]\n', "robot.toml")


def test_zones_are_live_and_a_bad_one_is_refused_naming_it() -> None:
    """`buddybot param set radar-presence zones '[...]'` applies at once; a bad
    zone is refused with what is wrong and where, the old zones kept."""
    new, changed = validate(RadarPresenceSettings(), {"zones": [msgspec.to_builtins(DOOR)]})
    assert changed == ["zones"] and new.zones == [DOOR]
    bad = {**msgspec.to_builtins(DOOR), "x": [3.0, 2.0]}
    with pytest.raises(ParamRefused, match=r"radar_presence.zones = .* refused: zone 'doorway': "
                                           r"x = \[3.0, 2.0\] is inverted.* at `zones\[1\]`"):
        validate(new, {"zones": [msgspec.to_builtins(ROOM), bad]})
    with pytest.raises(ParamRefused, match=r"refused: Expected `array`, got `str`"):
        validate(new, {"zones": "doorway"})
    cleared, _ = validate(new, {"zones": []})
    assert cleared.zones == []
