"""Drawing helpers of the simulated camera: the room behind the people, pasting a photo.

`world_view.WorldCamera` films the simulated world with these. The photo
in `data/` is a crop of `skimage.data.astronaut` (Eileen Collins, NASA,
public domain), the tests' reference face.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import cv2
import numpy as np

FACE_FILE = "astronaut_face.jpg"


def face_path() -> Path:
    return Path(str(resources.files("buddybot.camera") / "data" / FACE_FILE))


def background(width: int, height: int) -> np.ndarray:
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


def oval_mask(sprite: np.ndarray) -> np.ndarray:
    """A soft oval alpha mask the size of `sprite`: a face photo without its corners."""
    h, w = sprite.shape[:2]
    mask = np.zeros((h, w), np.float32)
    cv2.ellipse(mask, (w // 2, h // 2), (int(w * 0.47), int(h * 0.48)), 0, 0, 360, 1.0, -1)
    return cv2.GaussianBlur(mask, (0, 0), max(w, h) * 0.03)


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
