"""Pinhole geometry and the distance cues (pure)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import geometry as g


def test_intrinsics_default_principal_point_is_the_image_centre() -> None:
    k = g.Intrinsics.resolve(640, 480, fx=600.0, fy=None)
    assert (k.fx, k.fy, k.cx, k.cy) == (600.0, 600.0, 320.0, 240.0)


def test_intrinsics_from_a_horizontal_field_of_view() -> None:
    k = g.Intrinsics.resolve(640, 480, fx=None, hfov_deg=90.0)
    assert k.fx == pytest.approx(320.0)
    assert k.fy == pytest.approx(320.0)


@pytest.mark.parametrize("kwargs", [{"fx": None}, {"fx": -1.0}, {"fx": None, "hfov_deg": 180.0}])
def test_intrinsics_refuse_impossible_values(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        g.Intrinsics.resolve(640, 480, **kwargs)


def test_seed_distance_formula() -> None:
    assert g.distance_from_width(600.0, 0.15, 90.0) == pytest.approx(1.0)
    with pytest.raises(ValueError):
        g.distance_from_width(600.0, 0.15, 0.0)


def test_back_projection_uses_ros_axes() -> None:
    k = g.Intrinsics(600.0, 600.0, 320.0, 240.0)
    assert g.back_project(320, 240, 2.0, k) == pytest.approx((2.0, 0.0, 0.0))
    x, y, z = g.back_project(20, 40, 1.0, k)  # left of and above the centre
    assert x == 1.0
    assert y == pytest.approx(0.5)  # +y = left
    assert z == pytest.approx(1 / 3)  # +z = up
    _, y, z = g.back_project(620, 440, 1.0, k)
    assert y < 0 and z < 0


def _face(nose_x: float, right_ear_x: float = 0.0, left_ear_x: float = 100.0,
          eye_gap: float = 40.0, width: float = 100.0) -> bf.Detection:
    kps = np.zeros((6, 2), np.float32)
    kps[bf.RIGHT_EYE] = (50 - eye_gap / 2, 40)
    kps[bf.LEFT_EYE] = (50 + eye_gap / 2, 40)
    kps[bf.NOSE_TIP] = (nose_x, 60)
    kps[bf.RIGHT_EAR] = (right_ear_x, 50)
    kps[bf.LEFT_EAR] = (left_ear_x, 50)
    return bf.Detection((0.0, 0.0, width, width), 0.9, kps)


def test_head_yaw_is_zero_facing_and_signed_when_turned() -> None:
    assert g.head_yaw(_face(50).keypoints) == pytest.approx(0.0)
    t = math.radians(30)
    # Cylinder: nose at R sin t, ears at -+R cos t (R = 50, centre 50).
    kps = _face(50 + 50 * math.sin(t), 50 - 50 * math.cos(t), 50 + 50 * math.cos(t)).keypoints
    assert g.head_yaw(kps) == pytest.approx(t, abs=1e-6)
    assert g.head_yaw(_face(-500).keypoints) == pytest.approx(-math.radians(70))


def test_width_only_when_the_eye_cue_is_off() -> None:
    est = g.estimate_distance(_face(50), 600.0, 0.15, None)
    assert est.z_m == pytest.approx(0.9)
    assert est.from_eyes_m is None


def test_fusion_of_agreeing_cues_and_yaw_correction_of_the_eye_cue() -> None:
    # Frontal: 100 px box (0.15 m) and 42 px eyes (0.063 m) both say 0.9 m.
    est = g.estimate_distance(_face(50, eye_gap=42.0), 600.0, 0.15, 0.063)
    assert est.from_eyes_m == pytest.approx(0.9)
    assert est.z_m == pytest.approx(0.9)
    # Turned 40 degrees: the eyes look closer together by cos(40); the
    # corrected eye cue still says 0.9 m.
    t = math.radians(40)
    turned = _face(50 + 50 * math.sin(t), 50 - 50 * math.cos(t), 50 + 50 * math.cos(t),
                   eye_gap=42.0 * math.cos(t))
    est = g.estimate_distance(turned, 600.0, 0.15, 0.063)
    assert est.from_eyes_m == pytest.approx(0.9, rel=1e-4)
    assert est.z_m == pytest.approx(0.9, rel=1e-4)
