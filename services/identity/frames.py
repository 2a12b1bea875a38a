"""Camera frames kept for the faces found in them: a small ring by stamp, decoded on use.

The face detector publishes each frame's faces with the frame's own
`stamp_ns`, after the frame itself went out; the identity service keeps the
last few `Image` messages as they came (no decoding: most are never used)
and decodes only the one a face is embedded from (`contract.images`).
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from buddybot.contract import messages as m


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
