"""Frames checked and converted at the two edges of the camera area (no Zenoh).

Capture side, `to_bgr8`: whatever a source delivers (grey, BGRA, 16-bit,
any size) becomes the HxWx3 uint8 BGR the `Image` message promises, or is
refused with a reason. The other edge, an `Image` from the bus decoded
with its checks, is `contract.images.decode_image` (shared with the
identity service).

A refusal is a `FrameRefused` carrying a short `reason` (a diagnostics
counter name) and a sentence for the log.
"""

from __future__ import annotations

import cv2
import numpy as np

from buddybot.contract.images import FrameRefused
from buddybot.contract.messages import MAX_SIDE


def to_bgr8(frame: np.ndarray | None, max_side: int | None = MAX_SIDE) -> np.ndarray:
    """`frame` as HxWx3 uint8 BGR: grey and BGRA converted, 16-bit scaled to 8.

    Raises `FrameRefused` for an empty frame, an unknown channel count or
    pixel type, and a side above `max_side` (None: any size, for a frame
    that is resized next).
    """
    if frame is None or frame.size == 0:
        raise FrameRefused("bad_frames", "empty frame")
    if frame.ndim == 3 and frame.shape[2] == 1:
        frame = frame[:, :, 0]
    if frame.ndim not in (2, 3):
        raise FrameRefused("bad_frames", f"frame of shape {frame.shape}")
    if frame.dtype == np.uint16:
        frame = (frame >> 8).astype(np.uint8)
    elif frame.dtype != np.uint8:
        raise FrameRefused("bad_frames", f"pixel type {frame.dtype} (uint8 or uint16 expected)")
    h, w = frame.shape[:2]
    if max_side is not None and (w > max_side or h > max_side):
        raise FrameRefused("too_large", f"frame {w}x{h} is larger than {max_side} pixels a "
                           "side (set width/height to resize it)")
    if frame.ndim == 2:
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    channels = frame.shape[2]
    if channels == 3:
        return frame
    if channels == 4:
        return cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
    raise FrameRefused("bad_frames", f"frame with {channels} channels (1, 3 or 4 expected)")
