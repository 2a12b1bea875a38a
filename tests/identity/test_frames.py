"""Frames kept by stamp for the faces found in them, decoded only on use; bad bytes refused."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from buddybot.contract import messages as m
from buddybot.identity.frames import BadImage, ImageRing, to_bgr


def _image(stamp: int, w: int = 8, h: int = 6, encoding: str = "bgr8",
           data: bytes | None = None) -> m.Image:
    raw = data if data is not None else bytes(w * h * 3)
    return m.Image(stamp_ns=stamp, frame_id="front", width=w, height=h,
                   encoding=encoding, data=raw)  # type: ignore[arg-type]


def test_the_ring_keeps_the_last_images_by_stamp() -> None:
    ring = ImageRing(3)
    for stamp in range(5):
        ring.put(_image(stamp))
    assert ring.get(0) is None and ring.get(1) is None
    assert [ring.get(s).stamp_ns for s in (2, 3, 4)] == [2, 3, 4]  # type: ignore[union-attr]
    with pytest.raises(ValueError):
        ImageRing(0)


def test_bgr8_and_jpeg_decode() -> None:
    bgr = np.zeros((6, 8, 3), np.uint8)
    bgr[:, :, 2] = 200
    assert to_bgr(_image(1, data=bgr.tobytes())).shape == (6, 8, 3)
    ok, jpeg = cv2.imencode(".jpg", bgr)
    assert ok
    out = to_bgr(_image(1, encoding="jpeg", data=jpeg.tobytes()))
    assert out.shape == (6, 8, 3) and int(out[0, 0, 2]) > 150


@pytest.mark.parametrize("img", [
    _image(1, data=b"\0" * 10),
    _image(1, encoding="jpeg", data=b"garbage"),
    _image(1, w=16, encoding="jpeg",
           data=cv2.imencode(".jpg", np.zeros((6, 8, 3), np.uint8))[1].tobytes()),
])
def test_bytes_that_disagree_with_the_header_are_refused(img: m.Image) -> None:
    with pytest.raises(BadImage):
        to_bgr(img)
