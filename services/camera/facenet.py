"""The detection stage: one BGR image in, faces in image pixels out (no Zenoh, no capture).

Each call goes one way through three steps and never comes back:
prepare (letterbox into the input tensor) -> infer (LiteRT) -> decode
(anchors, weighted NMS; `blazeface.py`). The network wants a square RGB
input in [-1, 1], NHWC; the image is letterboxed (aspect kept, padded with
black) so faces are not squashed, and decoding maps coordinates back
through the same letterbox. OpenCV only resizes here; inference is LiteRT's
(`litert.py`), which runs these models about twice as fast as OpenCV DNN
did, and runs the sparse full-range model, which OpenCV DNN cannot load
(it has no DENSIFY operator).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera.litert import LiteModel, ModelLoadError, Tensor

__all__ = ["FaceNet", "ModelLoadError", "crop_square", "shrink"]


def shrink(bgr: np.ndarray, width: int, height: int) -> np.ndarray:
    """Resize to (width, height): halve with area averaging while the image is at
    least twice the target (fast and alias-free), then one bilinear step.

    A direct INTER_AREA resize by a non-integer factor costs ~3 ms for
    640x480 -> 192x144 here; this costs ~0.3 ms and keeps small faces sharp.
    """
    img = bgr
    while img.shape[1] >= 2 * width and img.shape[0] >= 2 * height:
        img = cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2),
                         interpolation=cv2.INTER_AREA)
    if (img.shape[1], img.shape[0]) == (width, height):
        return img
    return cv2.resize(img, (width, height), interpolation=cv2.INTER_LINEAR)


def crop_square(bgr: np.ndarray, cx: float, cy: float, side: float) -> tuple[np.ndarray, int, int]:
    """A `side`-pixel square centred at (cx, cy), padded with black where it leaves
    the image; returns it with its top-left corner in image pixels. A square
    inside the image is a view of it (read-only use: the caller only resizes it)."""
    s = max(round(side), 2)
    x0, y0 = round(cx - s / 2), round(cy - s / 2)
    h, w = bgr.shape[:2]
    if x0 >= 0 and y0 >= 0 and x0 + s <= w and y0 + s <= h:
        return bgr[y0:y0 + s, x0:x0 + s], x0, y0  # inside: a view, no copy
    ix0, iy0, ix1, iy1 = max(x0, 0), max(y0, 0), min(x0 + s, w), min(y0 + s, h)
    if ix1 <= ix0 or iy1 <= iy0:
        return np.zeros((s, s, 3), np.uint8), x0, y0
    part = bgr[iy0:iy1, ix0:ix1]
    out = cv2.copyMakeBorder(part, iy0 - y0, y0 + s - iy1, ix0 - x0, x0 + s - ix1,
                             cv2.BORDER_CONSTANT, value=(0, 0, 0))
    return out, x0, y0


def tensors(spec: bf.ModelSpec) -> tuple[Tensor, list[Tensor]]:
    """The layout a BlazeFace model of `spec` must have: one NHWC RGB input and two
    outputs, one score logit and 16 box/keypoint values per anchor (matched by shape:
    the tensor names differ between the dense, sparse and short models)."""
    n = spec.anchor_count
    size = spec.input_size
    return Tensor((1, size, size, 3)), [Tensor((1, n, 1)), Tensor((1, n, 16))]


class FaceNet:
    """One loaded BlazeFace model; `detect(bgr)` -> detections in image pixels.

    Raises `ModelLoadError` (a ConfigError: the service exits 2) when the file
    cannot be loaded or is not a BlazeFace model of `spec`'s layout.
    """

    def __init__(self, path: Path, spec: bf.ModelSpec, min_score: float | None = None,
                 num_threads: int = 1) -> None:
        self.spec = spec
        self.path = Path(path)
        self.min_score = spec.min_score if min_score is None else min_score
        expected_in, expected_out = tensors(spec)
        self.model = LiteModel(self.path, expected_in, expected_out, num_threads)
        self._anchors = bf.anchors(spec)
        self._input = np.full((1, spec.input_size, spec.input_size, 3), -1.0, np.float32)
        self._letterbox: bf.Letterbox | None = None
        self._shape: tuple[int, int] = (0, 0)
        self.inferences = 0

    def prepare(self, bgr: np.ndarray) -> bf.Letterbox:
        """Letterbox `bgr` (HxWx3 uint8) into the input tensor; returns the mapping back."""
        h, w = bgr.shape[:2]
        if self._letterbox is None or self._shape != (w, h):
            self._letterbox = bf.Letterbox.fit(w, h, self.spec.input_size)
            self._shape = (w, h)
            self._input.fill(-1.0)
        lb = self._letterbox
        rw, rh = lb.resized_shape(w, h)
        if self.spec.resize == "linear":
            small = cv2.resize(bgr, (rw, rh), interpolation=cv2.INTER_LINEAR)
        else:
            small = shrink(bgr, rw, rh)
        rgb = cv2.cvtColor(small, cv2.COLOR_BGR2RGB)
        px, py = int(lb.pad_x), int(lb.pad_y)
        region = self._input[0, py:py + rh, px:px + rw]
        np.multiply(rgb, 1.0 / 127.5, out=region, casting="unsafe")
        region -= 1.0
        return lb

    def _infer_and_decode(self, lb: bf.Letterbox, min_score: float,
                          max_faces: int) -> list[bf.Detection]:
        scores, boxes = self.model.run(self._input)
        self.inferences += 1
        return bf.postprocess(scores, boxes, self._anchors, self.spec, lb, min_score, max_faces)

    def detect(self, bgr: np.ndarray, max_faces: int = 16) -> list[bf.Detection]:
        """All faces in a BGR image, best score first."""
        if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8 or bgr.size == 0:
            raise ValueError(f"expected an HxWx3 uint8 BGR image, got {bgr.shape} {bgr.dtype}")
        return self._infer_and_decode(self.prepare(bgr), self.min_score, max_faces)

    def refine(self, bgr: np.ndarray, det: bf.Detection, context: float = 3.0,
               min_score: float = 0.3) -> bf.Detection | None:
        """Detect again in a square crop `context` face-widths wide around `det`.

        A far face is ~15 px wide in a full frame squeezed to 192 px, where
        box and eye keypoints are off by several image pixels; in the crop it
        fills a third of the input, so size and keypoints are precise. Returns
        the crop's best face whose centre lies within half a box of `det`'s,
        in image pixels, or None. (Whether that is plausibly the same face as
        a frame earlier is the tracking gate's question, not this one's.)
        """
        cx, cy = det.centre
        crop, x0, y0 = crop_square(bgr, cx, cy, context * max(det.width, det.height))
        for cand in self._infer_and_decode(self.prepare(crop), min_score, 4):
            found = cand.shifted(x0, y0)
            fcx, fcy = found.centre
            if abs(fcx - cx) < det.width / 2 and abs(fcy - cy) < det.height / 2:
                return found
        return None
