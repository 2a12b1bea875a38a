"""The tracking gate (pure): which crop results may continue a track."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera.gate import TrackGate

FX, FACE_W = 600.0, 0.15
DT = 1 / 30


def face(cx: float, cy: float, width: float, eye_gap: float | None = None,
         eye_y: float = -0.1) -> bf.Detection:
    """A square face box with eyes 0.4 box widths apart, a little above the centre."""
    gap = 0.4 * width if eye_gap is None else eye_gap
    kps = np.zeros((6, 2), np.float32)
    kps[bf.RIGHT_EYE] = (cx - gap / 2, cy + eye_y * width)
    kps[bf.LEFT_EYE] = (cx + gap / 2, cy + eye_y * width)
    h = width / 2
    return bf.Detection((cx - h, cy - h, cx + h, cy + h), 0.9, kps)


def check(prev: bf.Detection, cand: bf.Detection, dt: float = DT) -> str | None:
    return TrackGate().check(prev, cand, dt, FX, FACE_W)


def test_a_still_or_slowly_moving_face_passes() -> None:
    prev = face(200, 150, 90)  # 1.0 m
    assert check(prev, face(200, 150, 90)) is None
    assert check(prev, face(206, 152, 94)) is None  # 0.2 m/s sideways, a little closer
    assert check(prev, face(190, 150, 84)) is None  # detector noise of a few percent


def test_a_size_change_no_head_can_make_is_refused() -> None:
    # 1.0 m -> 0.6 m in one frame is 12 m/s.
    assert check(face(200, 150, 90), face(200, 150, 150)) == "size"
    # 0.6 m -> 2.0 m: the crop found a smaller face at the same place.
    assert check(face(320, 240, 150), face(315, 235, 45)) == "size"


def test_a_position_change_no_head_can_make_is_refused() -> None:
    assert check(face(200, 150, 90), face(200 + 0.9 * 90, 150, 90)) == "position"


def test_the_bounds_grow_with_the_time_between_frames() -> None:
    prev, cand = face(200, 150, 90), face(200, 150, 125)  # 1.0 m -> 0.72 m
    assert check(prev, cand, DT) == "size"
    assert check(prev, cand, 0.2) is None  # 1.4 m/s over 0.2 s: walking pace
    # A missing or backwards interval is taken as one frame, not as "no time, no bound".
    assert check(prev, cand, 0.0) == "size" and check(prev, cand, -5.0) == "size"
    # A long gap does not open the gate completely.
    assert check(prev, face(200, 150, 400), 100.0) == "size"


def test_keypoints_that_disagree_with_the_box_are_refused() -> None:
    prev = face(200, 150, 90)
    swapped = face(200, 150, 90, eye_gap=-36.0)  # eyes in the wrong order
    assert check(prev, swapped) == "keypoints"
    assert check(prev, face(200, 150, 90, eye_gap=12.0)) == "keypoints"  # eyes too close
    assert check(prev, face(200, 150, 90, eye_y=0.3)) == "keypoints"  # eyes at the chin
    assert check(prev, face(200, 150, 90, eye_gap=40.0, eye_y=-0.05)) is None  # small turn


@pytest.mark.parametrize("width", [0.0, -5.0])
def test_an_empty_box_is_refused(width: float) -> None:
    cand = bf.Detection((100.0, 100.0, 100.0 + width, 150.0), 0.9, np.zeros((6, 2), np.float32))
    assert check(face(100, 120, 60), cand) == "size"
