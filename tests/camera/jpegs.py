"""Real JPEGs and crafted ones for the header tests and the bomb tests, and the
pixels of a published image.

A "bomb" is a genuine small JPEG whose frame header (SOF) is rewritten to
claim a huge size: a decoder trusts the header, allocates the whole frame
and fills what the data does not cover.
"""

from __future__ import annotations

import cv2
import numpy as np

from buddybot.contract import jpeg
from buddybot.contract import messages as m


def encode(bgr: np.ndarray, quality: int = 85, progressive: bool = False) -> bytes:
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality,
                                         cv2.IMWRITE_JPEG_PROGRESSIVE, int(progressive)])
    assert ok
    return buf.tobytes()


def sof_offset(data: bytes) -> int:
    """Index of the first SOF marker's 0xFF byte (walks the segments by length)."""
    pos = 2
    while True:
        code = data[pos + 1]
        if code in jpeg.SOF_MARKERS:
            return pos
        pos += 2 + int.from_bytes(data[pos + 2:pos + 4], "big")


def with_size(data: bytes, width: int, height: int) -> bytes:
    """`data` with its frame header claiming width x height (the scan is unchanged)."""
    at = sof_offset(data) + 5  # FF Cx, length(2), precision(1), then height, width
    out = bytearray(data)
    out[at:at + 2] = height.to_bytes(2, "big")
    out[at + 2:at + 4] = width.to_bytes(2, "big")
    return bytes(out)


def bomb(width: int = 20000, height: int = 20000) -> bytes:
    """A ~700-byte colour JPEG whose header claims width x height pixels."""
    rng = np.random.default_rng(7)
    small = rng.integers(0, 255, (16, 16, 3), dtype=np.uint8)
    return with_size(encode(small, quality=50), width, height)


def bgr_of(msg: m.Image) -> np.ndarray:
    """The pixels of an image message, bgr8 or JPEG."""
    if msg.encoding == "bgr8":
        return np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.width, 3)
    return cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_COLOR)
