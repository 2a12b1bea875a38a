"""Unit tests of the camera->eyes transform and the gaze angles (signs!)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from buddybot.controller.transform import (
    RigidTransform,
    face_gaze,
    gaze_angles,
    rotation_from_rpy,
)

approx = pytest.approx


def test_straight_ahead_is_centre() -> None:
    g = gaze_angles((2.0, 0.0, 0.0))
    assert (g.yaw, g.pitch, g.distance_cm) == (0.0, 0.0, approx(200.0))


def test_face_on_the_robots_left_gives_positive_yaw() -> None:
    g = gaze_angles((1.0, 1.0, 0.0))
    assert g.yaw == approx(math.pi / 4)
    assert g.pitch == approx(0.0)


def test_face_on_the_right_gives_negative_yaw() -> None:
    assert gaze_angles((1.0, -0.5, 0.0)).yaw == approx(math.atan2(-0.5, 1.0))
    assert gaze_angles((1.0, -0.5, 0.0)).yaw < 0


def test_face_above_gives_positive_pitch_below_negative() -> None:
    up = gaze_angles((1.0, 0.0, 1.0))
    down = gaze_angles((3.0, 4.0, -5.0))
    assert up.pitch == approx(math.pi / 4)
    assert down.pitch == approx(math.atan2(-5.0, 5.0))
    assert down.distance_cm == approx(math.sqrt(50.0) * 100.0)


def test_behind_the_robot_is_yaw_pi() -> None:
    assert abs(gaze_angles((-1.0, 0.0, 0.0)).yaw) == approx(math.pi)


def test_origin_is_centre_not_an_error() -> None:
    g = gaze_angles((0.0, 0.0, 0.0))
    assert (g.yaw, g.pitch, g.distance_cm) == (0.0, 0.0, 0.0)


def test_identity_transform_keeps_points() -> None:
    t = RigidTransform.from_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert t.apply((1.0, 2.0, 3.0)) == approx((1.0, 2.0, 3.0))


def test_translation_camera_above_the_eyes() -> None:
    # Camera 10 cm above the eyes centre: a face level with the camera is above the eyes.
    t = RigidTransform.from_rpy((0.0, 0.0, 0.10), (0.0, 0.0, 0.0))
    p = t.apply((1.0, 0.0, 0.0))
    assert p == approx((1.0, 0.0, 0.10))
    assert gaze_angles(p).pitch == approx(math.atan2(0.10, 1.0))


def test_translation_camera_left_of_the_eyes() -> None:
    t = RigidTransform.from_rpy((0.0, 0.05, 0.0), (0.0, 0.0, 0.0))
    assert face_gaze(t, (1.0, 0.0, 0.0)).yaw == approx(math.atan2(0.05, 1.0))


def test_yaw_rotation_camera_turned_left() -> None:
    # Camera turned 90 deg to the left: its forward axis is the eyes' +y.
    t = RigidTransform.from_rpy((0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2))
    assert t.apply((1.0, 0.0, 0.0)) == approx((0.0, 1.0, 0.0), abs=1e-12)
    assert face_gaze(t, (1.0, 0.0, 0.0)).yaw == approx(math.pi / 2)


def test_pitch_rotation_camera_tilted_down() -> None:
    # ROS: positive pitch about +y tilts the x axis downward (toward -z).
    t = RigidTransform.from_rpy((0.0, 0.0, 0.0), (0.0, 0.3, 0.0))
    assert face_gaze(t, (1.0, 0.0, 0.0)).pitch == approx(-0.3)


def test_roll_rotation_maps_left_to_up() -> None:
    t = RigidTransform.from_rpy((0.0, 0.0, 0.0), (math.pi / 2, 0.0, 0.0))
    assert t.apply((0.0, 1.0, 0.0)) == approx((0.0, 0.0, 1.0), abs=1e-12)


def test_rotation_order_is_yaw_pitch_roll_fixed_axes() -> None:
    # R = Rz(yaw) Ry(pitch) Rx(roll): roll first, about the fixed x axis.
    r = rotation_from_rpy(math.pi / 2, 0.0, math.pi / 2)
    t = RigidTransform(r, (0.0, 0.0, 0.0))
    # y --roll 90--> z --yaw 90 (about z)--> z
    assert t.apply((0.0, 1.0, 0.0)) == approx((0.0, 0.0, 1.0), abs=1e-12)
    # x --roll--> x --yaw 90--> y
    assert t.apply((1.0, 0.0, 0.0)) == approx((0.0, 1.0, 0.0), abs=1e-12)


def test_rotation_then_translation() -> None:
    t = RigidTransform.from_rpy((0.1, 0.0, 0.0), (0.0, 0.0, math.pi))
    assert t.apply((1.0, 0.0, 0.0)) == approx((-0.9, 0.0, 0.0), abs=1e-12)


@pytest.mark.parametrize("bad", [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0)])
def test_non_finite_face_is_refused(bad: tuple[float, float, float]) -> None:
    with pytest.raises(ValueError, match="not finite"):
        face_gaze(RigidTransform(), bad)


def test_non_finite_config_is_refused() -> None:
    with pytest.raises(ValueError, match="non-finite"):
        RigidTransform.from_rpy((0.0, 0.0, 0.0), (math.nan, 0.0, 0.0))


finite = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)
angle = st.floats(min_value=-math.pi, max_value=math.pi, allow_nan=False)


@given(st.tuples(finite, finite, finite), st.tuples(angle, angle, angle),
       st.tuples(finite, finite, finite))
def test_rigid_transform_preserves_distances(
    p: tuple[float, float, float], rpy: tuple[float, float, float],
    trans: tuple[float, float, float],
) -> None:
    t = RigidTransform.from_rpy(trans, rpy)
    a, b = t.apply(p), t.apply((0.0, 0.0, 0.0))
    assert math.dist(a, b) == approx(math.hypot(*p), abs=1e-9)


@given(st.tuples(finite, finite, finite))
def test_angles_stay_in_the_message_ranges(p: tuple[float, float, float]) -> None:
    g = gaze_angles(p)
    assert -math.pi <= g.yaw <= math.pi
    assert -math.pi / 2 <= g.pitch <= math.pi / 2
    assert g.distance_cm == approx(math.hypot(*p) * 100.0)
