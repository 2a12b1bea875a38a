"""Frames kept by stamp for the faces found in them (decoding: tests/camera/test_frames.py)."""

from __future__ import annotations

import pytest

from buddybot.contract import messages as m
from buddybot.identity.frames import ImageRing


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
