"""Camera frames kept for the faces found in them: a small ring by stamp, decoded on use.

The face detector publishes each frame's faces with the frame's own
`stamp_ns`, after the frame itself went out; the identity service keeps the
last few `Image` messages as they came (no decoding: most are never used)
and decodes only the one a face is embedded from.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import cv2
import numpy as np

from buddybot.contract import jpeg
from buddybot.contract import messages as m


class BadImage(ValueError):
    """An image whose bytes do not hold what its header says."""


class ImageRing:
    """The last `size` images by stamp; thread-safe (put from one thread, get from others)."""

    def __init__(self, size: int = 8) -> None:
        if size < 1:
            raise ValueError("the ring holds at least one image")
        self.size = size
        self._images: OrderedDict[int, m.Image] = OrderedDict()
        self._lock = threading.Lock()

    def put(self, img: m.Image) -> None:
        with self._lock:
            self._images[img.stamp_ns] = img
            self._images.move_to_end(img.stamp_ns)
            while len(self._images) > self.size:
                self._images.popitem(last=False)

    def get(self, stamp_ns: int) -> m.Image | None:
        """The image of this stamp, None when it is not (or no longer) here."""
        with self._lock:
            return self._images.get(stamp_ns)


def to_bgr(img: m.Image) -> np.ndarray:
    """HxWx3 uint8 BGR of an `Image`; BadImage when its data and header disagree."""
    w, h = img.width, img.height
    if img.encoding == "bgr8":
        if len(img.data) != w * h * 3:
            raise BadImage(f"bgr8 {w}x{h} needs {w * h * 3} bytes, got {len(img.data)}")
        return np.frombuffer(img.data, np.uint8).reshape(h, w, 3)
    try:  # the JPEG's own header first: it, not the message, sizes the decoded frame
        header = jpeg.read_header(img.data)
    except jpeg.JpegError as exc:
        raise BadImage(f"jpeg {w}x{h}: {exc}") from None
    if (header.width, header.height) != (w, h):
        raise BadImage(f"jpeg header says {header.width}x{header.height}, the message {w}x{h}")
    try:
        bgr = cv2.imdecode(np.frombuffer(img.data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error as exc:
        raise BadImage(f"jpeg {w}x{h} does not decode: {exc}") from None
    if bgr is None or bgr.shape != (h, w, 3):
        raise BadImage(f"jpeg {w}x{h} does not decode to its stated size")
    return bgr
