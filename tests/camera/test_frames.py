"""Frames at the edges: what sources deliver (to_bgr8) and what the bus brings
(`contract.images.decode_image`, shared with the identity service), converted or
refused with a reason, never a crash."""

from __future__ import annotations

import io
import resource
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image as PilImage

from buddybot.camera import frames
from buddybot.contract import images
from buddybot.contract import messages as m
from tests.camera import jpegs

DATA = Path(__file__).parent / "data"
MAX = 3840 * 2160


def photo() -> np.ndarray:
    return cv2.imread(str(DATA / "grace_hopper.jpg"))


def jpeg_image(data: bytes, width: int, height: int) -> m.Image:
    return m.Image(stamp_ns=1, frame_id="cam", width=width, height=height, encoding="jpeg",
                   data=data)


# --- capture side ---------------------------------------------------------------------


def test_grey_bgra_single_channel_and_16_bit_frames_become_bgr8() -> None:
    bgr = photo()
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    bgra = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)
    for frame in (grey, grey[:, :, None], bgra, bgr, bgr.astype(np.uint16) * 257):
        out = frames.to_bgr8(frame)
        assert out.shape == (600, 512, 3) and out.dtype == np.uint8
    assert np.array_equal(frames.to_bgr8(bgra), bgr)
    assert np.array_equal(frames.to_bgr8(bgr.astype(np.uint16) * 257), bgr)
    assert np.array_equal(frames.to_bgr8(grey)[:, :, 1], grey)


@pytest.mark.parametrize(("frame", "says"), [
    (None, "empty"),
    (np.zeros((0, 640, 3), np.uint8), "empty"),
    (np.zeros((4, 4, 2), np.uint8), "2 channels"),
    (np.zeros((4, 4, 5), np.uint8), "5 channels"),
    (np.zeros((4, 4, 3, 2), np.uint8), "shape"),
    (np.zeros(16, np.uint8), "shape"),
    (np.zeros((4, 4, 3), np.float32), "pixel type float32"),
])
def test_unusable_frames_are_refused_with_a_reason(frame: np.ndarray | None, says: str) -> None:
    with pytest.raises(images.FrameRefused, match=says) as refused:
        frames.to_bgr8(frame)
    assert refused.value.reason == "bad_frames"


def test_a_frame_wider_than_the_message_allows_is_refused_unless_resized_next() -> None:
    wide = np.zeros((2, frames.MAX_SIDE + 1), np.uint8)
    with pytest.raises(images.FrameRefused) as refused:
        frames.to_bgr8(wide)
    assert refused.value.reason == "too_large"
    assert frames.to_bgr8(wide, max_side=None).shape == (2, frames.MAX_SIDE + 1, 3)


# --- detector side --------------------------------------------------------------------


def test_real_bgr8_baseline_progressive_and_grey_jpegs_decode() -> None:
    bgr = photo()
    raw = m.Image(stamp_ns=1, frame_id="cam", width=512, height=600, encoding="bgr8",
                  data=bgr.tobytes())
    assert np.array_equal(images.decode_image(raw, MAX), bgr)
    grey = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    cmyk = io.BytesIO()
    PilImage.fromarray(bgr[:, :, ::-1]).convert("CMYK").save(cmyk, "JPEG")
    for data in (jpegs.encode(bgr), jpegs.encode(bgr, progressive=True), jpegs.encode(grey),
                 (DATA / "grace_hopper.jpg").read_bytes(), cmyk.getvalue()):
        out = images.decode_image(jpeg_image(data, 512, 600), MAX)
        assert out.shape == (600, 512, 3) and out.dtype == np.uint8


def test_the_jpeg_bomb_is_refused_before_decoding() -> None:
    bomb = jpegs.bomb(20000, 20000)
    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(images.FrameRefused, match="20000x20000") as refused:
        images.decode_image(jpeg_image(bomb, 640, 480), MAX)
    assert refused.value.reason == "too_large"
    # A header that agrees with the message is still held to max_pixels.
    agreeing = jpegs.bomb(16000, 16000)
    with pytest.raises(images.FrameRefused) as refused:
        images.decode_image(jpeg_image(agreeing, 16000, 16000), MAX)
    assert refused.value.reason == "too_large"
    grown_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before
    assert grown_kib < 100 * 1024  # decoding either would have needed 0.8-1.2 GB


def test_max_pixels_is_the_setting_not_a_constant() -> None:
    small = jpegs.encode(photo())
    with pytest.raises(images.FrameRefused) as refused:
        images.decode_image(jpeg_image(small, 512, 600), 512 * 600 - 1)
    assert refused.value.reason == "too_large"
    assert images.decode_image(jpeg_image(small, 512, 600), 512 * 600).shape == (600, 512, 3)
    raw = m.Image(stamp_ns=1, frame_id="cam", width=512, height=600, encoding="bgr8",
                  data=photo().tobytes())
    with pytest.raises(images.FrameRefused):
        images.decode_image(raw, 1000)


@pytest.mark.parametrize(("image", "says"), [
    (m.Image(stamp_ns=1, frame_id="c", width=640, height=480, encoding="bgr8",
             data=b"\x00" * 100), "needs 921600 bytes, got 100"),
    (m.Image(stamp_ns=1, frame_id="c", width=640, height=480, encoding="bgr8",
             data=b"\x00" * (640 * 480 * 3 + 1)), "got 921601"),
    (m.Image(stamp_ns=1, frame_id="c", width=4, height=4, encoding="bgr8",
             data=b"\x00" * 16), "needs 48 bytes"),
    (m.Image(stamp_ns=1, frame_id="f" * 257, width=1, height=1, encoding="bgr8",
             data=b"\x00" * 3), "frame_id of 257 characters"),
    (jpeg_image(b"", 640, 480), "SOI"),
    (jpeg_image(b"\xff\xd8 broken jpeg", 640, 480), "expected a marker"),
    (jpeg_image(jpegs.encode(np.zeros((48, 64, 3), np.uint8)), 640, 480),
     "header says 64x48, the message 640x480"),
    (jpeg_image(jpegs.encode(np.zeros((48, 64, 3), np.uint8))[:200], 64, 48), "decode"),
])
def test_inconsistent_images_are_refused(image: m.Image, says: str) -> None:
    with pytest.raises(images.FrameRefused, match=says) as refused:
        images.decode_image(image, MAX)
    assert refused.value.reason == "bad_frames"
