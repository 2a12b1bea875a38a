"""Real LiteRT inference on real face photos composed at known places (no processes).

astronaut was used to tune; grace_hopper is held out (see scenes.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from skimage import data

from buddybot.camera import blazeface as bf
from buddybot.camera import draw, models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.litert import ModelLoadError
from buddybot.camera.pipeline import FacePipeline, OwedSearch
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.contract import jpeg
from tests.camera import scenes
from tests.camera.networks import Networks

PHOTOS: dict[str, Callable[[], scenes.Photo]] = {
    "astronaut": scenes.astronaut, "grace_hopper": scenes.grace_hopper,
}


@pytest.fixture(scope="module")
def full(networks: Networks) -> FaceNet:
    """The default whole-frame model: sparse full range."""
    return networks.face("full_sparse")


@pytest.fixture(scope="module")
def dense(networks: Networks) -> FaceNet:
    return networks.face("full")


@pytest.fixture(scope="module")
def short(networks: Networks) -> FaceNet:
    return networks.face("short")


def pipeline(full: FaceNet, short: FaceNet | None, **kw: object) -> FacePipeline:
    return FacePipeline(full, FaceDetectorSettings(smoothing=False, **kw), short)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", PHOTOS)
def test_detects_the_face_and_its_keypoints(full: FaceNet, name: str) -> None:
    photo = PHOTOS[name]()
    img, placed = scenes.scene(photo, 1.0)
    faces = full.detect(img)
    assert len(faces) == 1
    face = faces[0]
    assert face.score > 0.7
    right, left = face.keypoints[bf.RIGHT_EYE], face.keypoints[bf.LEFT_EYE]
    # eye keypoints within a quarter of the eye distance of the true pupils
    ipd = photo.ipd_px * placed.scale
    true_right = np.array([placed.u - ipd / 2, placed.v])
    true_left = np.array([placed.u + ipd / 2, placed.v])
    assert np.linalg.norm(right - true_right) < ipd / 4
    assert np.linalg.norm(left - true_left) < ipd / 4


@pytest.mark.parametrize("name", PHOTOS)
@pytest.mark.parametrize("z", [0.6, 1.0, 1.8])
def test_distance_within_10_percent(full: FaceNet, short: FaceNet, name: str, z: float) -> None:
    """With the default refinement (the full-range box alone is ~16% off at 1.8 m
    for the astronaut: see the accuracy table of benchmarks/faces.py)."""
    img, _ = scenes.scene(PHOTOS[name](), z)
    result = pipeline(full, short).process(img, 1)
    assert result.point is not None
    assert result.point[0] == pytest.approx(z, rel=0.10)


@pytest.mark.parametrize("z", [0.6, 1.0])
def test_short_range_model_alone(short: FaceNet, z: float) -> None:
    img, _ = scenes.scene(scenes.grace_hopper(), z)
    result = FacePipeline(short, FaceDetectorSettings(smoothing=False, model="short"),
                          short).process(img, 1)
    assert result.point is not None and result.point[0] == pytest.approx(z, rel=0.10)


@pytest.mark.parametrize("name", PHOTOS)
@pytest.mark.parametrize(("u", "v"), [(140, 240), (500, 240), (320, 120), (320, 360),
                                      (150, 130)])
def test_lateral_and_vertical_offsets_have_ros_signs(full: FaceNet, short: FaceNet, name: str,
                                                     u: float, v: float) -> None:
    img, placed = scenes.scene(PHOTOS[name](), 1.0, u, v)
    result = pipeline(full, short).process(img, 1)
    assert result.point is not None
    _x, y, z = result.point
    _tx, ty, tz = scenes.truth(placed)
    # The point is the face box centre, a little below the eyes' midpoint.
    assert y == pytest.approx(ty, abs=0.03)
    assert z == pytest.approx(tz - 0.035, abs=0.03)
    if u < 320:
        assert y > 0.1  # face on the image's left = robot's left = +y
    if u > 320:
        assert y < -0.1
    if v < 240:
        assert z > 0.05  # above the centre = +z
    if v > 240:
        assert z < -0.1


def test_principal_point_and_focal_length_from_config(full: FaceNet, short: FaceNet) -> None:
    img, _placed = scenes.scene(scenes.astronaut(), 1.0, 320, 240, fx=500.0)
    result = pipeline(full, short, fx=500.0, fy=500.0, cx=220.0, cy=240.0).process(img, 1)
    assert result.point is not None
    assert result.point[0] == pytest.approx(1.0, rel=0.1)
    assert result.point[1] == pytest.approx(-(320 - 220) / 500.0, abs=0.03)


@pytest.mark.parametrize("picture", ["background", "coffee", "brick", "rocket"])
def test_no_face_no_position(full: FaceNet, short: FaceNet, picture: str) -> None:
    if picture == "background":
        img = scenes.background()
    else:
        rgb = getattr(data, picture)()
        rgb = np.dstack([rgb] * 3) if rgb.ndim == 2 else rgb
        img = cv2.resize(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), (640, 480))
    result = pipeline(full, short).process(img, 1)
    assert result.faces == [] and result.point is None


@pytest.mark.parametrize("full_every_s", [0.0, 0.25], ids=["whole-frame", "crop-tracking"])
def test_two_faces_choose_the_nearer_then_stay_with_them(full: FaceNet, short: FaceNet,
                                                         full_every_s: float) -> None:
    pipe = pipeline(full, short, full_every_s=full_every_s)
    chosen_y, seen = [], []
    for i in range(12):
        # The astronaut (left) starts nearer; Grace Hopper (right) walks closer
        # until she is nearer still: the choice must not change.
        frame, _ = scenes.scene(scenes.astronaut(), 1.0, 170, 240)
        frame, _ = scenes.place(frame, scenes.grace_hopper(), 1.6 - 0.08 * i, 470, 240)
        result = pipe.process(frame, (i + 1) * 33_000_000)
        assert result.point is not None
        chosen_y.append(result.point[1])
        seen.append(len(result.faces))
    assert all(y > 0 for y in chosen_y), chosen_y  # always the one on the left
    assert pipe.tracker.target_changes == 1
    # Whole-frame passes see both faces; crop-tracking frames only the followed one.
    # 12 frames 33 ms apart, a whole-frame pass every 0.25 s: frames 1 and 9.
    expected = [2] * 12 if full_every_s == 0 else [2 if i in (0, 8) else 1 for i in range(12)]
    assert seen == expected
    assert pipe.tracked == expected.count(1)


def test_crop_tracking_follows_a_moving_face_like_the_whole_frame(full: FaceNet,
                                                                   short: FaceNet) -> None:
    """Tracking in the crop gives the same positions as searching the whole frame."""
    tracking = pipeline(full, short, full_every_s=0.25)
    whole = pipeline(full, short, full_every_s=0.0)
    for i in range(15):
        frame, placed = scenes.scene(scenes.astronaut(), 1.2, 200 + 15 * i, 230 + 4 * i)
        a = tracking.process(frame, (i + 1) * 33_000_000)
        b = whole.process(frame, (i + 1) * 33_000_000)
        assert a.point is not None and b.point is not None
        assert np.allclose(a.point, b.point, atol=0.06), (i, a.point, b.point)
        truth = scenes.truth(placed)
        assert abs(a.point[1] - truth[1]) < 0.05 and abs(a.point[0] - truth[0]) < 0.12
    assert tracking.tracked >= 10 and whole.tracked == 0


def test_debug_rendering_draws_on_a_copy(full: FaceNet, short: FaceNet) -> None:
    img, _ = scenes.scene(scenes.astronaut(), 1.0)
    result = pipeline(full, short).process(img, 1)
    out = draw.render(img, result.faces, result.target, result.estimate, result.measured)
    assert out.shape == img.shape and not np.array_equal(out, img)
    data = jpeg.encode(out, 80)
    assert data is not None and cv2.imdecode(np.frombuffer(data, np.uint8), 1).shape == img.shape


def test_a_file_that_is_not_a_model_is_refused(tmp_path: Path) -> None:
    bogus = tmp_path / "bogus.tflite"
    bogus.write_bytes(b"not a flatbuffer at all" * 10)
    with pytest.raises(ModelLoadError):
        FaceNet(bogus, bf.FULL_RANGE)


def test_the_wrong_model_for_the_spec_is_refused() -> None:
    with pytest.raises(ModelLoadError, match=r"wrong tensor layout.*expected input 1x192x192x3"):
        FaceNet(models.locate("short"), bf.FULL_RANGE)


@pytest.mark.parametrize("name", PHOTOS)
@pytest.mark.parametrize("z", [0.6, 1.0, 1.8])
def test_dense_full_range_model_still_selectable(dense: FaceNet, short: FaceNet, name: str,
                                                 z: float) -> None:
    img, _ = scenes.scene(PHOTOS[name](), z)
    result = FacePipeline(dense, FaceDetectorSettings(smoothing=False, model="full"),
                          short).process(img, 1)
    assert result.point is not None and result.point[0] == pytest.approx(z, rel=0.10)


def test_sparse_and_dense_decode_to_the_same_place(full: FaceNet, dense: FaceNet) -> None:
    """Same anchors and decoding for both full-range networks: the boxes agree."""
    img, placed = scenes.scene(scenes.grace_hopper(), 1.0, 250, 200)
    a, b = full.detect(img), dense.detect(img)
    assert len(a) == len(b) == 1
    assert np.allclose(a[0].centre, b[0].centre, atol=0.1 * b[0].width)
    assert a[0].width == pytest.approx(b[0].width, rel=0.15)
    assert abs(a[0].centre[0] - placed.u) < 0.1 * a[0].width


@pytest.mark.parametrize("bad", [np.zeros((10, 10), np.uint8), np.zeros((4, 4, 3), np.float32)])
def test_bad_arrays_are_refused(full: FaceNet, bad: np.ndarray) -> None:
    with pytest.raises(ValueError):
        full.detect(bad)


@pytest.mark.parametrize("shape", [(1, 400, 3), (400, 1, 3), (1, 1, 3), (2000, 30, 3)])
def test_odd_frame_shapes_do_not_break_detection(full: FaceNet, short: FaceNet,
                                                 shape: tuple[int, int, int]) -> None:
    img = np.full(shape, 128, np.uint8)
    assert pipeline(full, short).process(img, 1).point is None


def test_deferred_search_answers_from_the_crop_then_searches_off_the_latency_path(
    full: FaceNet, short: FaceNet
) -> None:
    """The detector service answers every frame after the first from the crop and does
    the due whole-frame pass after publishing (the owed work, `run_owed`)."""
    pipe = pipeline(full, short, full_every_s=0.25)
    searched = []
    for i in range(12):
        frame, _ = scenes.scene(scenes.astronaut(), 1.2, 200 + 8 * i, 240)
        result = pipe.process(frame, (i + 1) * 33_000_000, defer=True)
        assert result.point is not None and result.point[1] > 0
        found = pipe.run_owed(result.owed)
        searched.append(None if found is None else len(found))
    assert pipe.tracked == 11  # only the very first frame waited for a whole-frame pass
    assert searched == [None if i != 8 else 1 for i in range(12)]


def test_deferred_search_drops_a_track_the_whole_frame_does_not_confirm(
    full: FaceNet, short: FaceNet
) -> None:
    pipe = pipeline(full, short, full_every_s=0.25)
    frame, _ = scenes.scene(scenes.astronaut(), 1.2, 300, 240)
    for i in range(9):
        owed = pipe.process(frame, (i + 1) * 33_000_000, defer=True).owed
    assert pipe.tracked == 8
    [search] = owed
    assert isinstance(search, OwedSearch)
    # The due pass sees no face (here: an empty frame): the track is dropped ...
    assert pipe.run_owed([replace(search, bgr=scenes.background())]) == []
    # ... so the next frame is searched whole again instead of tracked.
    result = pipe.process(frame, 10 * 33_000_000, defer=True)
    assert pipe.tracked == 8 and len(result.faces) == 1 and result.point is not None


@pytest.mark.parametrize("shape", [(1, 400, 3), (400, 1, 3), (1, 1, 3), (2000, 30, 3)])
def test_odd_frame_shapes_render_a_debug_image(shape: tuple[int, int, int]) -> None:
    img = np.full(shape, 128, np.uint8)
    data = jpeg.encode(draw.render(img, [], None, None), 80)
    assert data is not None and cv2.imdecode(np.frombuffer(data, np.uint8), 1).shape == shape


@pytest.mark.parametrize("wrong_ns", [2**63 - 1, 15_000_000_000], ids=["max", "15s-ahead"])
def test_one_wrong_stamp_does_not_freeze_the_followed_face(full: FaceNet, short: FaceNet,
                                                           wrong_ns: int) -> None:
    """With smoothing and crop tracking, as the service runs: after one frame stamped
    far ahead, later frames must move the published point again at once."""
    pipe = FacePipeline(full, FaceDetectorSettings(), short)
    t0 = 1_700_000_000_000_000_000
    left, _ = scenes.scene(scenes.grace_hopper(), 1.2, 220, 240)
    for i in range(8):
        pipe.run_owed(pipe.process(left, t0 + i * 33_000_000, defer=True).owed)
    wrong = t0 + wrong_ns if wrong_ns < 2**62 else wrong_ns
    pipe.run_owed(pipe.process(left, wrong, defer=True).owed)
    right, placed = scenes.scene(scenes.grace_hopper(), 1.2, 420, 240)
    ys = []
    for i in range(9, 25):  # half a second of frames with the person moved right
        stamp = t0 + i * 33_000_000
        result = pipe.process(right, stamp, defer=True)
        pipe.run_owed(result.owed)
        if result.point is not None:
            ys.append(result.point[1])
    assert ys, "the moved face was never published"
    assert ys[-1] == pytest.approx(scenes.truth(placed)[1], abs=0.05)


def test_a_new_frame_size_every_frame_does_not_grow_the_pipeline(full: FaceNet) -> None:
    pipe = pipeline(full, None)
    frame, _ = scenes.scene(scenes.astronaut(), 1.0)
    for i in range(40):
        result = pipe.process(frame[: 400 + i, : 500 + i], i * 33_000_000)
        assert result.point is not None
    assert len(pipe._intrinsics) <= 8 and pipe._intrinsics.evicted >= 32
