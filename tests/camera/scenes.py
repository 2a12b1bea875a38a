"""Real face photos composed at known distances and positions (test data).

Ground truth comes from the photos, not from the detector: the pupils of
each photo were located by hand (zoomed crops), and a person with the
adult mean inter-pupillary distance (63 mm) at distance Z in front of a
camera with focal length fx shows `fx * 0.063 / Z` pixels between the
pupils. Scaling the photo to that and pasting it with the eyes' midpoint
at a chosen pixel gives a frame whose true 3-D face position is known.

* astronaut (scikit-image, NASA, public domain): used for tuning;
* grace_hopper (US Navy photo, public domain; the copy matplotlib ships as
  sample data, saved in data/ so the tests need no matplotlib): held out,
  never used to choose a parameter.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from skimage import data

from buddybot.camera.sim import compose

IPD_M = 0.063
WIDTH, HEIGHT = 640, 480


@dataclass(frozen=True)
class Photo:
    name: str
    bgr: np.ndarray
    right_pupil: tuple[float, float]  # subject's right eye (image left)
    left_pupil: tuple[float, float]

    @property
    def ipd_px(self) -> float:
        return float(np.hypot(self.left_pupil[0] - self.right_pupil[0],
                              self.left_pupil[1] - self.right_pupil[1]))

    @property
    def eyes_mid(self) -> tuple[float, float]:
        return ((self.right_pupil[0] + self.left_pupil[0]) / 2,
                (self.right_pupil[1] + self.left_pupil[1]) / 2)


def astronaut() -> Photo:
    bgr = cv2.cvtColor(data.astronaut(), cv2.COLOR_RGB2BGR)
    return Photo("astronaut", bgr, (203.1, 101.3), (246.3, 103.1))


def grace_hopper() -> Photo:
    path = Path(__file__).parent / "data" / "grace_hopper.jpg"
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert bgr is not None, path
    return Photo("grace_hopper", bgr, (223.3, 188.3), (304.2, 185.8))


def background(width: int = WIDTH, height: int = HEIGHT, seed: int = 0) -> np.ndarray:
    """A textured non-face backdrop (noise + stripes), deterministic."""
    rng = np.random.default_rng(seed)
    img = rng.integers(60, 120, (height, width, 3), dtype=np.uint8)
    img = cv2.GaussianBlur(img, (0, 0), 3)
    for x in range(0, width, 80):
        cv2.rectangle(img, (x, 0), (x + 30, height), (150, 140, 120), -1)
    return img


@dataclass(frozen=True)
class Placed:
    """A face put into a frame: where its eyes' midpoint is and how far it is."""

    u: float
    v: float
    z_m: float
    scale: float


def place(frame: np.ndarray, photo: Photo, z_m: float, u: float, v: float,
          fx: float = 600.0) -> tuple[np.ndarray, Placed]:
    """Paste `photo` as if the person stood `z_m` away with the eyes' midpoint at (u, v)."""
    scale = fx * IPD_M / z_m / photo.ipd_px
    h, w = photo.bgr.shape[:2]
    mx, my = photo.eyes_mid
    cx = u + (w / 2 - mx) * scale
    cy = v + (h / 2 - my) * scale
    # Feathered ellipse so the photo's straight edges do not stand out.
    mask = np.zeros((h, w), np.float32)
    cv2.ellipse(mask, (int(mx), int(my + 0.4 * photo.ipd_px)),
                (int(photo.ipd_px * 2.2), int(photo.ipd_px * 2.8)), 0, 0, 360, 1.0, -1)
    mask = cv2.GaussianBlur(mask, (0, 0), photo.ipd_px * 0.2)
    return compose(frame, photo.bgr, mask, cx, cy, h * scale), Placed(u, v, z_m, scale)


def scene(photo: Photo, z_m: float, u: float = WIDTH / 2, v: float = HEIGHT / 2,
          fx: float = 600.0, seed: int = 0) -> tuple[np.ndarray, Placed]:
    return place(background(seed=seed), photo, z_m, u, v, fx)


def truth(p: Placed, fx: float = 600.0, fy: float = 600.0, cx: float = WIDTH / 2,
          cy: float = HEIGHT / 2) -> tuple[float, float, float]:
    """True ROS point (x fwd, y left, z up) of the eyes' midpoint."""
    return p.z_m, -(p.u - cx) * p.z_m / fx, -(p.v - cy) * p.z_m / fy
