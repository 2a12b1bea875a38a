"""The map's geometry: camera frame (x forward, y left) -> canvas (u right, v down)."""

from __future__ import annotations

import math

import pytest

from buddybot.dashboard import map_geometry as geo


def test_forward_is_up_and_the_robots_left_is_drawn_left() -> None:
    view = geo.MapView(800, 740, 400, 680, 100)
    assert view.to_canvas(0, 0) == (400, 680)
    assert view.to_canvas(2, 0) == (400, 480)      # 2 m ahead: 200 px up
    assert view.to_canvas(0, 1) == (300, 680)      # 1 m to the robot's left: left
    assert view.to_canvas(0, -1) == (500, 680)
    assert view.to_canvas(-1, 0) == (400, 780)     # behind: below
    assert view.to_world(*view.to_canvas(1.5, -0.7)) == pytest.approx((1.5, -0.7))


def test_an_absurd_point_stays_a_small_finite_number() -> None:
    view = geo.MapView(800, 740, 400, 680, 100)
    u, v = view.to_canvas(1000, -1000)
    assert abs(u) <= geo.LIMIT_PX and abs(v) <= geo.LIMIT_PX
    assert not view.contains(u, v)


def test_the_view_fits_the_farthest_point_in_whole_metres() -> None:
    view = geo.fit_view(800, 740, [(2.0, 1.3), (4.2, 0.6), (3.0, -2.6)])
    assert view.origin_u == 400 and view.origin_v == 740 - geo.ROBOT_PX  # bottom centre
    # 2.6 m sideways -> 3 m; 4.2 m ahead -> 5 m: the tighter of the two sets the scale.
    assert view.scale == pytest.approx(min((400 - geo.EDGE_PX) / 3, (680 - geo.EDGE_PX) / 5))
    for x, y in [(2.0, 1.3), (4.2, 0.6), (3.0, -2.6)]:
        assert view.contains(*view.to_canvas(x, y))
    # Nothing yet: the minimum extents; something far beyond the sensor: capped.
    empty = geo.fit_view(800, 740, [])
    assert empty.scale == pytest.approx(min(380 / geo.MIN_SIDE_M, 660 / geo.MIN_EXTENT_M))
    far = geo.fit_view(800, 740, [(500.0, 0.0)])
    assert far.scale == pytest.approx(660 / geo.MAX_EXTENT_M)


def test_something_behind_the_robot_moves_it_to_the_centre() -> None:
    view = geo.fit_view(800, 740, [(-2.0, 0.5), (1.0, 0.0)])
    assert (view.origin_u, view.origin_v) == (400, 370)
    assert view.contains(*view.to_canvas(-2.0, 0.5))


def test_a_wedge_starts_at_the_robot_and_leaves_the_canvas() -> None:
    view = geo.fit_view(800, 740, [])
    left, right = math.radians(30), math.radians(-20)
    poly = geo.wedge(view, left, right, steps=10)
    assert poly[0] == view.to_canvas(0, 0)
    assert len(poly) == 12
    for u, v in poly[1:]:
        assert not view.contains(u, v)
    first, last = poly[1], poly[-1]
    # Right edge first (drawn right of the robot), left edge last (drawn left).
    assert first[0] > view.origin_u > last[0]
    x, y = view.to_world(*last)
    assert math.atan2(y, x) == pytest.approx(left)


def test_a_rectangle_of_the_camera_frame() -> None:
    view = geo.MapView(800, 740, 400, 680, 100)
    poly = geo.rectangle(view, 2.6, 3.6, 1.6, 2.6)
    assert poly == [(240, 420), (240, 320), (140, 320), (140, 420)]


def test_rings_every_metre_up_to_the_canvas_corners() -> None:
    view = geo.MapView(800, 740, 400, 680, 100)
    r = geo.rings(view)
    assert r[0] == 1.0 and r[1] == 2.0
    assert r[-1] < view.reach_m() <= r[-1] + 1.0
    wide = geo.MapView(800, 740, 400, 680, 40)  # 10 m to each side: every 2 m
    assert geo.rings(wide)[:2] == [2.0, 4.0]


@pytest.mark.parametrize(("width", "fx", "cx", "hfov", "expected_deg"), [
    (640, 600.0, None, None, (28.07, -28.07)),         # fx over the frame width
    (640, 600.0, 300.0, None, (26.57, -29.54)),        # off-centre principal point
    (None, 600.0, None, 70.0, (35.0, -35.0)),          # hfov_deg alone: symmetric
    (640, 600.0, None, 70.0, (35.0, -35.0)),           # hfov_deg wins over fx
])
def test_the_cameras_view_from_the_face_detectors_intrinsics(
        width: int | None, fx: float, cx: float | None, hfov: float | None,
        expected_deg: tuple[float, float]) -> None:
    fov = geo.camera_fov(width, fx, cx, hfov)
    assert fov is not None
    assert [math.degrees(a) for a in fov] == pytest.approx(expected_deg, abs=0.01)


@pytest.mark.parametrize(("width", "fx", "cx", "hfov"), [
    (None, 600.0, None, None),      # no width and no hfov_deg: unknown
    (640, None, None, None),
    (640, 0.0, None, None),
    (640, math.inf, None, None),
    (0, 600.0, None, None),
    (640, 600.0, None, 180.0),
    (640, 600.0, math.nan, None),
])
def test_an_unknown_or_absurd_camera_gives_no_view(
        width: int | None, fx: float | None, cx: float | None, hfov: float | None) -> None:
    assert geo.camera_fov(width, fx, cx, hfov) is None
