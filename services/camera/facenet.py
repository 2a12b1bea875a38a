"""Run a BlazeFace model with OpenCV DNN on one BGR image (no Zenoh, no capture).

`cv2.dnn.readNetFromTFLite(path, cv2.dnn.ENGINE_CLASSIC)`: the newer DNN
engine drops one of the model's two outputs. The network wants a square
RGB input in [-1, 1], NCHW; the image is letterboxed (aspect kept, padded
with black) so faces are not squashed, and the decoder maps coordinates
back through the same letterbox.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from buddybot.camera import blazeface as bf


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
    the image; returns it with its top-left corner in image pixels."""
    s = max(round(side), 2)
    x0, y0 = round(cx - s / 2), round(cy - s / 2)
    h, w = bgr.shape[:2]
    ix0, iy0, ix1, iy1 = max(x0, 0), max(y0, 0), min(x0 + s, w), min(y0 + s, h)
    if ix1 <= ix0 or iy1 <= iy0:
        return np.zeros((s, s, 3), np.uint8), x0, y0
    part = bgr[iy0:iy1, ix0:ix1]
    out = cv2.copyMakeBorder(part, iy0 - y0, y0 + s - iy1, ix0 - x0, x0 + s - ix1,
                             cv2.BORDER_CONSTANT, value=(0, 0, 0))
    return out, x0, y0


class ModelLoadError(Exception):
    """The file exists but OpenCV cannot load it as a BlazeFace model."""


class FaceNet:
    """One loaded BlazeFace model; `detect(bgr)` -> detections in image pixels."""

    def __init__(self, path: Path, spec: bf.ModelSpec, min_score: float | None = None) -> None:
        self.spec = spec
        self.path = path
        self.min_score = spec.min_score if min_score is None else min_score
        try:
            self._net = cv2.dnn.readNetFromTFLite(str(path), cv2.dnn.ENGINE_CLASSIC)
        except cv2.error as exc:
            raise ModelLoadError(f"cannot load {path}: {exc}") from None
        self._outputs = list(self._net.getUnconnectedOutLayersNames())
        self._anchors = bf.anchors(spec)
        self._input = np.full((1, 3, spec.input_size, spec.input_size), -1.0, np.float32)
        self._letterbox: bf.Letterbox | None = None
        self._shape: tuple[int, int] = (0, 0)
        self._check_outputs()

    def _check_outputs(self) -> None:
        """Run once on a blank input: wrong output shapes mean a wrong model."""
        scores, boxes = self._forward()
        n = len(self._anchors)
        if scores.size != n or boxes.size != n * 16:
            raise ModelLoadError(
                f"{self.path}: outputs {scores.shape}/{boxes.shape} do not match the "
                f"{self.spec.name}-range BlazeFace layout ({n} anchors)"
            )

    def _forward(self) -> tuple[np.ndarray, np.ndarray]:
        self._net.setInput(self._input)
        outs = self._net.forward(self._outputs)
        a, b = outs[0], outs[1]
        # Scores have 1 value per anchor, boxes 16: order by size, not by name.
        return (a, b) if a.size < b.size else (b, a)

    def prepare(self, bgr: np.ndarray) -> bf.Letterbox:
        """Letterbox `bgr` into the input tensor; returns the mapping back."""
        h, w = bgr.shape[:2]
        if self._letterbox is None or self._shape != (w, h):
            self._letterbox = bf.Letterbox.fit(w, h, self.spec.input_size)
            self._shape = (w, h)
            self._input.fill(-1.0)
        lb = self._letterbox
        rw, rh = lb.resized_shape(w, h)
        small = shrink(bgr, rw, rh)
        blob = cv2.dnn.blobFromImage(small, 1.0 / 127.5, (rw, rh), (127.5, 127.5, 127.5),
                                     swapRB=True, crop=False)
        px, py = int(lb.pad_x), int(lb.pad_y)
        self._input[:, :, py:py + rh, px:px + rw] = blob
        return lb

    def detect(self, bgr: np.ndarray, max_faces: int = 16) -> list[bf.Detection]:
        """All faces in a BGR image, best score first."""
        if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
            raise ValueError(f"expected an HxWx3 uint8 BGR image, got {bgr.shape} {bgr.dtype}")
        lb = self.prepare(bgr)
        scores, boxes = self._forward()
        return bf.postprocess(scores, boxes, self._anchors, self.spec, lb, self.min_score,
                              max_faces)

    def refine(self, bgr: np.ndarray, det: bf.Detection, context: float = 3.0,
               min_score: float = 0.3) -> bf.Detection | None:
        """Detect again in a square crop `context` face-widths wide around `det`.

        A far face is ~15 px wide in a full frame squeezed to 192 px, where
        box and eye keypoints are off by several image pixels; in the crop it
        fills a third of the input, so size and keypoints are precise. Returns
        the crop's best face overlapping `det`, in image pixels, or None.
        """
        cx, cy = det.centre
        crop, x0, y0 = crop_square(bgr, cx, cy, context * max(det.width, det.height))
        lb = self.prepare(crop)
        scores, boxes = self._forward()
        found = bf.postprocess(scores, boxes, self._anchors, self.spec, lb, min_score, 4)
        best = None
        for cand in found:
            box = (cand.box[0] + x0, cand.box[1] + y0, cand.box[2] + x0, cand.box[3] + y0)
            ccx, ccy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
            if abs(ccx - cx) < det.width / 2 and abs(ccy - cy) < det.height / 2:
                best = bf.Detection(box, cand.score,
                                    cand.keypoints + np.array([x0, y0], np.float32))
                break
        return best
