"""A face that jumps between two frames, real LiteRT inference.

Without the tracking gate, crop tracking publishes a face at 0.6 m as 1.67,
2.38 and 3.67 m after such a jump, and then loses it for ~10 frames. The
requirement: no published distance more than 15% off the truth, and the
face published again within 2 frames of the jump.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.gate import TrackGate
from buddybot.camera.pipeline import FacePipeline
from buddybot.camera.settings import FaceDetectorSettings
from tests.camera import scenes

PHOTOS: dict[str, Callable[[], scenes.Photo]] = {
    "astronaut": scenes.astronaut, "grace_hopper": scenes.grace_hopper,
}
FRAME_NS = 33_333_333
BEFORE = 8  # frames of the first face (crop tracking is on by then)


@pytest.fixture(scope="module")
def nets() -> tuple[FaceNet, FaceNet]:
    return (FaceNet(models.locate("full_sparse"), bf.FULL_SPARSE),
            FaceNet(models.locate("short"), bf.SHORT_RANGE))


class OpenGate(TrackGate):
    """No gate: every crop result continues the track (the behaviour before the gate)."""

    def check(self, prev: bf.Detection, cand: bf.Detection, dt_s: float, fx: float,
              face_width_m: float) -> str | None:
        return None


def run_jump(nets: tuple[FaceNet, FaceNet], photo: scenes.Photo,
             first: tuple[float, float, float], second: tuple[float, float, float],
             gate: TrackGate | None = None, frames: int = 16,
             ) -> tuple[FacePipeline, list[tuple[float, float, float] | None], float]:
    """`first` (z, u, v) for BEFORE frames, then `second`; the service's way of calling
    (deferred whole-frame search, smoothing on). Returns the published points after the
    jump and the true distance."""
    full, short = nets
    pipe = FacePipeline(full, FaceDetectorSettings(), short, gate)
    a, _ = scenes.scene(photo, *first)
    b, placed = scenes.scene(photo, *second)
    published: list[tuple[float, float, float] | None] = []
    for i in range(frames):
        frame = a if i < BEFORE else b
        stamp = 1_700_000_000_000_000_000 + i * FRAME_NS
        result = pipe.process(frame, stamp, defer=True)
        pipe.run_owed(result.owed)
        if i < BEFORE:
            assert result.point is not None, f"first face not published in frame {i}"
        else:
            published.append(result.point)
    return pipe, published, placed.z_m


def assert_recovered(published: list[tuple[float, float, float] | None], z: float) -> None:
    assert all(p is not None for p in published[:2]), published[:2]
    for i, p in enumerate(published):
        if p is not None:
            assert abs(p[0] - z) <= 0.15 * z, (i, p[0], z)


@pytest.mark.parametrize("name", PHOTOS)
def test_upper_left_90px_to_lower_right_150px(nets: tuple[FaceNet, FaceNet],
                                              name: str) -> None:
    """90 px (1.0 m) at the upper left, then 150 px (0.6 m) at the lower right: the
    new face must not be held back for switch_after_s as if it were a bystander."""
    pipe, published, z = run_jump(nets, PHOTOS[name](), (1.0, 130, 120), (0.6, 470, 330))
    assert_recovered(published, z)
    assert pipe.tracked >= BEFORE - 2  # crop tracking was really on before the jump


@pytest.mark.parametrize("name", PHOTOS)
@pytest.mark.parametrize("second", [(1.5, 330, 250), (2.0, 300, 230)], ids=["1.5m", "2m"])
def test_a_smaller_face_at_the_same_place_is_not_taken_as_the_crop_track(
    nets: tuple[FaceNet, FaceNet], name: str, second: tuple[float, float, float]
) -> None:
    """Someone close (0.6 m) leaves and someone farther away is at nearly the same place
    in the image: the crop finds the new face, the gate refuses it (size), the whole
    frame is searched and the new face is published at its own distance."""
    pipe, published, z = run_jump(nets, PHOTOS[name](), (0.6, 320, 240), second)
    assert_recovered(published, z)
    assert pipe.gate_rejections["size"] >= 1


def test_without_the_gate_the_same_scene_publishes_a_wrong_distance(
    nets: tuple[FaceNet, FaceNet]
) -> None:
    """The check above can fail: with every crop result accepted, smoothing runs across
    the jump and the first published distances are far off."""
    _pipe, published, z = run_jump(nets, scenes.astronaut(), (0.6, 320, 240),
                                   (2.0, 300, 230), OpenGate())
    with pytest.raises(AssertionError):
        assert_recovered(published, z)


def test_a_face_walking_at_a_normal_pace_stays_crop_tracked(
    nets: tuple[FaceNet, FaceNet]
) -> None:
    """The gate must not refuse real motion: 1.2 m/s towards the camera and sideways."""
    full, short = nets
    pipe = FacePipeline(full, FaceDetectorSettings(smoothing=False), short)
    errors = []
    for i in range(20):
        z = 2.0 - 0.04 * i
        frame, _ = scenes.scene(scenes.grace_hopper(), z, 200 + 6 * i, 240)
        result = pipe.process(frame, (i + 1) * FRAME_NS, defer=True)
        pipe.run_owed(result.owed)
        assert result.point is not None
        errors.append(abs(result.point[0] - z) / z)
    assert sum(pipe.gate_rejections.values()) == 0, pipe.gate_rejections
    assert pipe.tracked >= 17 and float(np.max(errors)) < 0.12
