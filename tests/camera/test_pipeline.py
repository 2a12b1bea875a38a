"""The face pipeline (one frame in, at most one face out, and the work owed once it is
published), with real LiteRT inference on composed photos (scenes.py), no processes.

* Frames of any size and kind: processed or refused with a counted reason, never an
  exception; what the networks are given.
* A face that jumps between two frames. Without the tracking gate, crop tracking
  publishes a face at 0.6 m as 1.67, 2.38 and 3.67 m after such a jump, and then loses
  it for ~10 frames. The requirement: no published distance more than 15% off the
  truth, and the face published again within 2 frames of the jump.
* The iris stage: measured when due, held, reset, and used. The iris and fusion maths
  have their own tests (test_iris.py, test_fusion.py); these check the wiring: that
  the pipeline measures at the right moments, that what it learns reaches the
  published distance, and that it forgets it for a new person.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import msgspec
import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import draw, fusion
from buddybot.camera.facenet import FaceNet
from buddybot.camera.gate import TrackGate
from buddybot.camera.iris import IrisNet
from buddybot.camera.pipeline import FacePipeline, OwedIris
from buddybot.camera.settings import FaceDetectorSettings
from tests.camera import scenes
from tests.camera.networks import Networks


@pytest.fixture(scope="module")
def nets(networks: Networks) -> tuple[FaceNet, FaceNet]:
    return networks.face("full_sparse"), networks.face("short")


def unsmoothed(nets: tuple[FaceNet, FaceNet]) -> FacePipeline:
    """A pipeline that publishes each frame's own measurement (no smoothing)."""
    return FacePipeline(nets[0], FaceDetectorSettings(smoothing=False), nets[1])


def face_frame() -> np.ndarray:
    return scenes.scene(scenes.grace_hopper(), 1.0)[0]


@pytest.mark.parametrize("convert", [
    lambda bgr: cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY),
    lambda bgr: cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)[:, :, None],
    lambda bgr: cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA),
    lambda bgr: bgr.astype(np.uint16) * 257,
    lambda bgr: np.ascontiguousarray(bgr[:, ::-1]),  # a non-default stride order too
], ids=["grey", "grey-1-channel", "bgra", "16-bit", "mirrored"])
def test_grey_four_channel_and_16_bit_frames_are_processed(nets: tuple[FaceNet, FaceNet],
                                                           convert: object) -> None:
    pipe = unsmoothed(nets)
    result = pipe.process(convert(face_frame()), 1)  # type: ignore[operator]
    assert result.refused is None and result.point is not None
    assert result.point[0] == pytest.approx(1.0, rel=0.12)
    assert not pipe.refused


@pytest.mark.parametrize("frame", [
    np.zeros((0, 0, 3), np.uint8), np.zeros((0, 640, 3), np.uint8), np.zeros((0, 0), np.uint8),
    np.zeros((48, 64, 2), np.uint8), np.zeros((48, 64, 5), np.uint8),
    np.zeros((48, 64, 3), np.float32), np.zeros((2, 48, 64, 3), np.uint8),
    np.zeros((64,), np.uint8),
], ids=["0x0", "0x640", "0x0-grey", "2-channel", "5-channel", "float", "4-d", "1-d"])
def test_unusable_frames_are_refused_and_counted(nets: tuple[FaceNet, FaceNet],
                                                 frame: np.ndarray) -> None:
    pipe = unsmoothed(nets)
    result = pipe.process(frame, 1)
    assert result.refused == "bad_frames" and result.point is None and result.faces == []
    assert pipe.refused["bad_frames"] == 1
    assert result.owed == ()  # nothing owed for a refused frame


@pytest.mark.parametrize("shape", [(1, 1), (1, 5000), (5000, 1), (3, 7), (2161, 3841)])
def test_any_size_is_processed(nets: tuple[FaceNet, FaceNet], shape: tuple[int, int]) -> None:
    pipe = unsmoothed(nets)
    frame = np.full((*shape, 3), 90, np.uint8)
    result = pipe.process(frame, 1, defer=True)
    assert result.refused is None and result.point is None


def test_a_bad_frame_between_good_ones_does_not_disturb_tracking(
    nets: tuple[FaceNet, FaceNet]
) -> None:
    pipe = FacePipeline(nets[0], FaceDetectorSettings(), nets[1])
    good = face_frame()
    points = []
    for i in range(12):
        frame = np.zeros((0, 0, 3), np.uint8) if i == 5 else good
        result = pipe.process(frame, (i + 1) * 33_333_333, defer=True)
        pipe.run_owed(result.owed)
        if i != 5:
            assert result.point is not None
            points.append(result.point)
    assert pipe.refused["bad_frames"] == 1 and pipe.tracked >= 9
    assert np.allclose(points[-1], points[0], atol=0.03)


def _expected_input(bgr: np.ndarray, size: int) -> np.ndarray:
    """The network input by the plain rule: bilinear resize, BGR -> RGB, [-1, 1],
    black (-1) letterbox border."""
    lb = bf.Letterbox.fit(bgr.shape[1], bgr.shape[0], size)
    rw, rh = lb.resized_shape(bgr.shape[1], bgr.shape[0])
    rgb = cv2.resize(bgr, (rw, rh), interpolation=cv2.INTER_LINEAR)[:, :, ::-1]
    out = np.full((size, size, 3), -1.0, np.float32)
    px, py = int(lb.pad_x), int(lb.pad_y)
    out[py:py + rh, px:px + rw] = rgb / 127.5 - 1.0
    return out


def test_the_input_tensor_is_the_letterboxed_picture_whatever_the_order_of_shapes(
        nets: tuple[FaceNet, FaceNet]) -> None:
    """Landscape (border above/below: the OpenCV path), portrait (border left/right:
    the NumPy path) and square (no border, not refilled) frames in turn: each time
    the whole tensor is that frame's letterbox, with no rows left from the last."""
    net = nets[0]
    rng = np.random.default_rng(3)
    shapes = [(480, 640), (640, 480), (300, 300), (480, 640), (300, 300), (640, 480)]
    for h, w in shapes:
        bgr = rng.integers(0, 256, (h, w, 3), np.uint8)
        net.detect(bgr)
        assert net.input_tensor() == pytest.approx(_expected_input(bgr, 192), abs=1e-5), (w, h)


def test_a_crop_reaches_the_refiner_as_a_resized_crop_with_black_outside(
        nets: tuple[FaceNet, FaceNet]) -> None:
    """The refiner's one-warp crop is the crop `cv2.resize` would give (within one grey
    level), and black (-1) where the square leaves the frame; a whole-frame pass in
    between does not leave its letterbox border in the crop's tensor or vice versa."""
    short = nets[1]
    frame = face_frame()
    det = nets[0].detect(frame)[0]
    cx, cy = det.centre
    side = 3 * max(det.width, det.height)
    s = round(side)
    x0, y0 = round(cx - s / 2), round(cy - s / 2)
    assert x0 >= 0 and y0 >= 0 and x0 + s <= frame.shape[1] and y0 + s <= frame.shape[0]
    short.refine(frame, det)
    want = cv2.resize(frame[y0:y0 + s, x0:x0 + s], (128, 128),
                      interpolation=cv2.INTER_LINEAR)[:, :, ::-1] / 127.5 - 1.0
    assert np.abs(short.input_tensor() - want).max() <= 1.01 / 127.5
    short.detect(frame)  # letterboxed whole frame: border rows of -1
    assert short.input_tensor()[0] == pytest.approx(-1.0)
    # The same face at the left edge: the crop's left part lies outside the frame.
    shifted = np.zeros_like(frame)
    dx = int(det.box[0]) - 2
    shifted[:, :frame.shape[1] - dx] = frame[:, dx:]
    edge = nets[0].detect(shifted)[0]
    short.refine(shifted, edge)
    tensor = short.input_tensor()
    assert tensor[:, :10] == pytest.approx(-1.0)  # outside: black
    assert tensor[40:90, 60:100].std() > 0.05  # the face: a picture, not a border


# --- a face that jumps -----------------------------------------------------------------


PHOTOS: dict[str, Callable[[], scenes.Photo]] = {
    "astronaut": scenes.astronaut, "grace_hopper": scenes.grace_hopper,
}
FRAME_NS = 33_333_333
BEFORE = 8  # frames of the first face (crop tracking is on by then)


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


# --- the iris stage --------------------------------------------------------------------


FX = 600.0


@pytest.fixture(scope="module")
def parts(nets: tuple[FaceNet, FaceNet], networks: Networks) -> tuple[FaceNet, FaceNet, IrisNet]:
    return (*nets, networks.iris())


def pipeline(parts: tuple[FaceNet, FaceNet, IrisNet], iris: bool = True,
             **changes: object) -> FacePipeline:
    settings = msgspec.structs.replace(FaceDetectorSettings(), fx=FX, fy=FX, iris=iris,
                                       **changes)
    net, refiner, irises = parts
    return FacePipeline(net, settings, refiner, irises=irises if iris else None)


def frames_at(photo: scenes.Photo, z: float, count: int, u: float = 320.0,
              v: float = 240.0) -> list[np.ndarray]:
    return [scenes.scene(photo, z, u, v, FX, seed=i)[0] for i in range(count)]


def run(p: FacePipeline, imgs: list[np.ndarray], start_s: float = 100.0,
        period_s: float = 1 / 30) -> list[object]:
    return [p.process(img, round((start_s + i * period_s) * 1e9)) for i, img in enumerate(imgs)]


def test_a_close_face_is_measured_every_iris_every_s_and_the_iris_is_used(parts) -> None:
    p = pipeline(parts, iris_every_s=0.5)
    results = run(p, frames_at(scenes.astronaut(), 0.4, 31))  # one second at 30 fps
    assert p.iris_measurements == 3  # at 0, 0.5 and 1.0 s
    assert p.iris_accepted >= 2
    last = results[-1].estimate
    assert last is not None and last.fusion is not None
    assert fusion.IRIS_HELD in last.fusion.used
    assert last.fusion.weight(fusion.IRIS_HELD) > 0.2
    assert last.z_m == pytest.approx(0.4, rel=0.05)
    assert fusion.IRIS_HELD in last.fusion.summary()


def test_iris_off_means_no_measurement_and_no_iris_cue(parts) -> None:
    p = pipeline(parts, iris=False)
    results = run(p, frames_at(scenes.astronaut(), 0.4, 10))
    assert p.iris_measurements == 0
    last = results[-1].estimate
    assert last is not None and last.fusion is not None
    assert set(last.fusion.used) == {fusion.WIDTH, fusion.EYES}


def test_a_far_face_is_not_measured(parts) -> None:
    """At 2 m the iris is ~3.5 px: the stage would cost 6 ms for nothing."""
    p = pipeline(parts)
    run(p, frames_at(scenes.astronaut(), 2.0, 20))
    assert p.iris_measurements == 0


def test_deferred_processing_measures_only_after_publishing(parts) -> None:
    p = pipeline(parts)
    img = frames_at(scenes.astronaut(), 0.4, 1)[0]
    first = p.process(img, 100_000_000_000, defer=True)
    assert first.target is not None and p.iris_measurements == 0
    [owed] = first.owed
    assert isinstance(owed, OwedIris) and owed.measured is first.measured
    assert p.run_owed(first.owed) is None  # no whole-frame pass was owed
    assert p.iris_measurements == 1
    second = p.process(img, 100_033_000_000, defer=True)  # within iris_every_s: not owed
    assert not any(isinstance(work, OwedIris) for work in second.owed)


def test_a_new_person_is_not_measured_with_the_last_ones_iris(parts) -> None:
    """The held ratio belongs to one person: after a switch it must be learnt again."""
    p = pipeline(parts, iris_every_s=10.0)
    run(p, frames_at(scenes.astronaut(), 0.6, 3, u=470.0))
    first = p.iris_held.ipd_m
    assert first is not None
    # Nobody for a while, then somebody else, elsewhere in the frame (more than a
    # box width away: the tracker takes a face near the old place for the same person).
    empty = [scenes.background(seed=7)] * 30
    run(p, empty, start_s=101.0)
    hopper = frames_at(scenes.grace_hopper(), 0.5, 1, u=140.0, v=220.0)
    result = p.process(hopper[0], 103_000_000_000)
    assert result.target is not None
    # Measured at once for the newcomer (schedule reset) and from their own eyes.
    assert p.iris_measurements == 2
    second = p.iris_held.ipd_m
    # Her own eye distance (~68.6 mm on this photo), not a blend with the astronaut's (~62.6).
    assert second is not None and abs(second - first) > 0.003


def test_the_debug_image_names_the_cues(parts) -> None:
    p = pipeline(parts)
    imgs = frames_at(scenes.astronaut(), 0.4, 2)
    results = run(p, imgs)
    last = results[-1]
    plain = draw.render(imgs[-1], last.faces, last.target, None, last.measured)
    named = draw.render(imgs[-1], last.faces, last.target, last.estimate, last.measured)
    bottom = slice(imgs[-1].shape[0] - 30, imgs[-1].shape[0])
    assert np.any(plain[bottom] != named[bottom])  # the summary line is drawn there
