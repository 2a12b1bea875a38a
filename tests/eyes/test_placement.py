"""Which eye goes on which display (services/eyes/placement.py), pure: display lists in,
windows out."""

from __future__ import annotations

import pytest

from buddybot.eyes import placement
from buddybot.eyes.placement import Display, PlacementError, Request, plan

D1 = Display(0, 0, 800, 480, "HDMI-1")


D2 = Display(800, 0, 800, 480, "HDMI-2")


D3 = Display(1600, 0, 1024, 600, "DP-1")


def windows(displays: list[Display], request: Request | None = None) -> list[tuple[str, int]]:
    return [(w.eye, w.display_number) for w in plan(displays, request or Request())]


def test_default_two_displays_left_on_1_right_on_2() -> None:
    assert windows([D1, D2]) == [("left", 1), ("right", 2)]
    # Numbered left to right whatever order the OS lists them in.
    assert plan([D2, D1])[0].display == D1
    assert windows([D3, D2, D1]) == [("left", 1), ("right", 2)]


def test_one_display_no_option_both_eyes_on_it() -> None:
    (win,) = plan([D2])
    assert (win.eye, win.display_number, win.display) == ("both", 1, D2)


def test_no_display_is_an_error() -> None:
    with pytest.raises(PlacementError, match=r"no display found.*--no-browser"):
        plan([])
    with pytest.raises(PlacementError, match="no display"):
        plan([], Request(eyes=("left",)))


def test_more_eyes_configured_than_displays_is_an_error() -> None:
    with pytest.raises(PlacementError, match=r"2 eyes configured .* only 1 display"):
        plan([D1], Request(eyes=("left", "right")))
    with pytest.raises(PlacementError, match="2 eyes configured"):
        plan([D1], Request(left_display=1))


def test_display_number_that_does_not_exist_is_an_error() -> None:
    with pytest.raises(PlacementError, match="right eye configured on display 3 but only 2"):
        plan([D1, D2], Request(right_display=3))
    with pytest.raises(PlacementError, match="left eye configured on display 0"):
        plan([D1, D2], Request(left_display=0))


def test_options_choose_displays_and_eyes() -> None:
    assert windows([D1, D2], Request(left_display=2, right_display=1)) == [
        ("left", 2), ("right", 1)]
    assert windows([D1, D2, D3], Request(right_display=3)) == [("left", 1), ("right", 3)]
    assert windows([D1, D2, D3], Request(left_display=2)) == [("left", 2), ("right", 1)]
    assert windows([D1], Request(eyes=("right",))) == [("right", 1)]
    assert windows([D1, D2], Request(eyes=("left",), left_display=2)) == [("left", 2)]
    # Both explicitly on one display: one window with both eyes.
    assert windows([D1, D2], Request(left_display=2, right_display=2)) == [("both", 2)]
    assert windows([D1], Request(left_display=1, right_display=1)) == [("both", 1)]


def test_geometry_parsing() -> None:
    d = placement.parse_geometry("1024x600+1920+0")
    assert (d.width, d.height, d.x, d.y) == (1024, 600, 1920, 0)
    for bad in ("1024x600", "axb+0+0", "0x600+0+0", "", "10x10+1+2+3"):
        with pytest.raises(ValueError, match="WIDTHxHEIGHT"if bad != "0x600+0+0" else "positive"):
            placement.parse_geometry(bad)
