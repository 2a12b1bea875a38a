"""Sensor x/y -> the camera's frame: axes, bearing sign, mount pose (pure)."""

from __future__ import annotations

import math

import pytest

from buddybot.radar.mounting import IDENTITY, Mount, place


def test_straight_ahead_is_bearing_zero() -> None:
    p = place(0.0, 2.0)
    assert (p.x, p.y, p.z, p.bearing_rad, p.distance_m) == pytest.approx((2.0, 0.0, 0.0, 0.0, 2.0))


def test_negative_x_is_the_robots_left_and_a_positive_bearing() -> None:
    left = place(-1.0, 1.0, IDENTITY)
    assert left.y > 0 and left.bearing_rad == pytest.approx(math.pi / 4)
    right = place(1.0, 1.0)
    assert right.y < 0 and right.bearing_rad == pytest.approx(-math.pi / 4)


def test_mirror_x_flips_the_side() -> None:
    assert place(-1.0, 1.0, Mount(mirror_x=True)).bearing_rad == pytest.approx(-math.pi / 4)


def test_yaw_and_position() -> None:
    # A sensor on the robot's left side (0.1 m left, 0.2 m below), facing left.
    mount = Mount(x=0.0, y=0.1, z=-0.2, yaw=math.pi / 2)
    p = place(0.0, 2.0, mount)  # 2 m straight out of the sensor: to the robot's left
    assert (p.x, p.y, p.z) == pytest.approx((0.0, 2.1, -0.2), abs=1e-9)
    assert p.bearing_rad == pytest.approx(math.pi / 2) and p.distance_m == pytest.approx(2.1)
    behind = place(0.0, 1.0, Mount(x=-0.5, yaw=math.pi))
    assert behind.x == pytest.approx(-1.5) and abs(behind.bearing_rad) == pytest.approx(math.pi)
