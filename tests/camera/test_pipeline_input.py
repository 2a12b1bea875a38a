"""Frames of any size and kind given to the pipeline: processed or refused with a
counted reason, never an exception (real LiteRT inference, no processes)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.pipeline import FacePipeline
from buddybot.camera.settings import FaceDetectorSettings
from tests.camera import scenes


@pytest.fixture(scope="module")
def nets() -> tuple[FaceNet, FaceNet]:
    return (FaceNet(models.locate("full_sparse"), bf.FULL_SPARSE),
            FaceNet(models.locate("short"), bf.SHORT_RANGE))


def pipeline(nets: tuple[FaceNet, FaceNet]) -> FacePipeline:
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
    pipe = pipeline(nets)
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
    pipe = pipeline(nets)
    result = pipe.process(frame, 1)
    assert result.refused == "bad_frames" and result.point is None and result.faces == []
    assert pipe.refused["bad_frames"] == 1
    assert result.owed == ()  # nothing owed for a refused frame


@pytest.mark.parametrize("shape", [(1, 1), (1, 5000), (5000, 1), (3, 7), (2161, 3841)])
def test_any_size_is_processed(nets: tuple[FaceNet, FaceNet], shape: tuple[int, int]) -> None:
    pipe = pipeline(nets)
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
