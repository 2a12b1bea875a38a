"""An `Image` from the bus as BGR pixels, checked before any decoding (no Zenoh).

Every consumer of camera frames (the face detector, the identity service)
decodes through here, so no sample, however small on the wire, can make a
process allocate more than `max_pixels` frames' worth of memory: the
message's size and the JPEG's own frame header are checked first.

A refusal is a `FrameRefused` carrying a short `reason` (a diagnostics
counter name) and a sentence for the log.
"""

from __future__ import annotations

from typing import Literal

import cv2
import numpy as np

from buddybot.contract import jpeg
from buddybot.contract import messages as m

DEFAULT_MAX_PIXELS = 3840 * 2160
"""Largest frame a consumer decodes unless configured otherwise (4K)."""

FRAME_ID_MAX = 256
"""Characters of `frame_id`: it is copied into every face message, so an image
carrying megabytes of it would make every face message oversized."""

Reason = Literal["bad_frames", "too_large"]


class FrameRefused(Exception):
    """A frame that is not processed; `reason` names the counter it goes to."""

    def __init__(self, reason: Reason, text: str) -> None:
        super().__init__(text)
        self.reason: Reason = reason
        self.text = text


def decode_image(img: m.Image, max_pixels: int) -> np.ndarray:
    """The frame of an `Image` as HxWx3 uint8 BGR, checked before decoding.

    Refused (`FrameRefused`): a `frame_id` longer than `FRAME_ID_MAX`; more
    than `max_pixels` pixels (by the message or by the JPEG's own frame
    header); bgr8 data whose length is not width*height*3; a JPEG whose
    header is broken or disagrees with the message's width/height; a JPEG
    that does not decode.
    """
    w, h = img.width, img.height
    if len(img.frame_id) > FRAME_ID_MAX:
        raise FrameRefused("bad_frames", f"frame_id of {len(img.frame_id)} characters "
                           f"(at most {FRAME_ID_MAX})")
    if w * h > max_pixels:
        raise FrameRefused("too_large", f"image {w}x{h} has {w * h} pixels, above "
                           f"max_pixels {max_pixels}")
    if img.encoding == "bgr8":
        expected = w * h * 3
        if len(img.data) != expected:
            raise FrameRefused("bad_frames", f"bgr8 image {w}x{h} needs {expected} bytes, "
                               f"got {len(img.data)}")
        return np.frombuffer(img.data, np.uint8).reshape(h, w, 3)
    try:
        header = jpeg.read_header(img.data)
    except jpeg.JpegError as exc:
        raise FrameRefused("bad_frames", f"jpeg {w}x{h} of {len(img.data)} bytes: {exc}") from None
    if header.pixels > max_pixels:
        raise FrameRefused("too_large", f"jpeg header says {header.width}x{header.height} "
                           f"({header.pixels} pixels), above max_pixels {max_pixels}")
    if (header.width, header.height) != (w, h):
        raise FrameRefused("bad_frames", f"jpeg header says {header.width}x{header.height}, "
                           f"the message {w}x{h}")
    try:
        bgr = cv2.imdecode(np.frombuffer(img.data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error as exc:
        raise FrameRefused("bad_frames", f"jpeg {w}x{h} does not decode: {exc}") from None
    if bgr is None or bgr.ndim != 3 or bgr.shape != (h, w, 3):
        raise FrameRefused("bad_frames", f"jpeg {w}x{h} does not decode to its stated size")
    return bgr
