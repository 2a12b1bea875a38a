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
        small = cv2.resize(bgr, (rw, rh), interpolation=cv2.INTER_AREA
                           if rw < w else cv2.INTER_LINEAR)
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
