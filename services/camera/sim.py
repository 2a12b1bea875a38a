"""Simulated camera: a real face photo gliding over a background, for `--sim`.

The photo is a crop of `skimage.data.astronaut` (Eileen Collins, NASA,
public domain) saved in `data/` so the simulation needs no scikit-image
at run time. The face moves left/right and up/down on slow, incommensurate
sine paths and changes size (as if walking nearer and further), so the
real detector runs on it and the eyes visibly follow. Frames are a pure
function of time: tests can ask for the frame at any `t`.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import cv2
import numpy as np

FACE_FILE = "astronaut_face.jpg"


def face_path() -> Path:
    return Path(str(resources.files("buddybot.camera") / "data" / FACE_FILE))


def _background(width: int, height: int) -> np.ndarray:
    """A calm room-like backdrop: a vertical gradient, a 'window' and a 'shelf'."""
    ramp = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None]
    top = np.array([200, 190, 170], np.float32)
    bottom = np.array([90, 110, 130], np.float32)
    img = (top * (1 - ramp[..., None]) + bottom * ramp[..., None])
    img = np.broadcast_to(img, (height, width, 3)).astype(np.uint8).copy()
    cv2.rectangle(img, (width // 12, height // 10), (width // 3, height // 2), (230, 220, 200), -1)
    cv2.rectangle(img, (width // 12, height // 10), (width // 3, height // 2), (80, 80, 80), 3)
    cv2.rectangle(img, (width * 2 // 3, height * 2 // 3), (width - width // 12,
                  height * 2 // 3 + 12), (40, 70, 110), -1)
    return img


class SimCamera:
    """Frames of the simulated scene; `frame(t)` for t in seconds."""

    def __init__(self, width: int = 640, height: int = 480, face: Path | None = None) -> None:
        self.width, self.height = width, height
        sprite = cv2.imread(str(face or face_path()), cv2.IMREAD_COLOR)
        if sprite is None:
            raise FileNotFoundError(f"simulated camera: cannot read {face or face_path()}")
        self._sprite = sprite
        h, w = sprite.shape[:2]
        mask = np.zeros((h, w), np.float32)
        cv2.ellipse(mask, (w // 2, h // 2), (int(w * 0.47), int(h * 0.48)), 0, 0, 360, 1.0, -1)
        self._mask = cv2.GaussianBlur(mask, (0, 0), max(w, h) * 0.03)
        self._background = _background(width, height)

    def placement(self, t: float) -> tuple[float, float, float]:
        """(centre x, centre y, sprite height) in pixels at time t."""
        cx = self.width / 2 + self.width * 0.28 * math.sin(2 * math.pi * t / 7.0)
        cy = self.height / 2 + self.height * 0.12 * math.sin(2 * math.pi * t / 4.3)
        size = self.height * (0.5 + 0.15 * math.sin(2 * math.pi * t / 11.0))
        return cx, cy, size

    def frame(self, t: float) -> np.ndarray:
        cx, cy, size = self.placement(t)
        return compose(self._background, self._sprite, self._mask, cx, cy, size)


def compose(background: np.ndarray, sprite: np.ndarray, mask: np.ndarray | None,
            cx: float, cy: float, height: float) -> np.ndarray:
    """Paste `sprite` scaled to `height` pixels, centred at (cx, cy), clipped to the frame."""
    out = background.copy()
    sh, sw = sprite.shape[:2]
    scale = height / sh
    w, h = max(1, round(sw * scale)), max(1, round(sh * scale))
    small = cv2.resize(sprite, (w, h), interpolation=cv2.INTER_AREA if scale < 1
                       else cv2.INTER_LINEAR)
    alpha = None if mask is None else cv2.resize(mask, (w, h), interpolation=cv2.INTER_LINEAR)
    x0, y0 = round(cx - w / 2), round(cy - h / 2)
    bx0, by0 = max(x0, 0), max(y0, 0)
    bx1, by1 = min(x0 + w, out.shape[1]), min(y0 + h, out.shape[0])
    if bx1 <= bx0 or by1 <= by0:
        return out
    part = small[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0]
    if alpha is None:
        out[by0:by1, bx0:bx1] = part
        return out
    a = alpha[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0, None]
    region = out[by0:by1, bx0:bx1].astype(np.float32)
    out[by0:by1, bx0:bx1] = (part * a + region * (1.0 - a)).astype(np.uint8)
    return out
