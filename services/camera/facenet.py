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

import dataclasses
from collections.abc import Callable
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
                 num_threads: int = 1, input_size: int | None = None) -> None:
        self.path = Path(path)
        self.min_score = spec.min_score if min_score is None else min_score
        expected_in, expected_out = tensors(spec)
        self.model = LiteModel(self.path, expected_in, expected_out, num_threads)
        if input_size is not None and input_size != spec.input_size:
            # BlazeFace is fully convolutional: at another input size it predicts on
            # correspondingly smaller anchor grids (same strides), decoded the same way.
            spec = dataclasses.replace(spec, input_size=input_size)
            self.model.resize_input(*tensors(spec))
        self.spec = spec
        self._anchors = bf.anchors(spec)
        self._letterbox: bf.Letterbox | None = None
        """The letterbox whose border the input tensor holds (None: none known)."""
        self._shape: tuple[int, int] = (0, 0)
        self.inferences = 0

    def _letterbox_into(self, bgr: np.ndarray, x: np.ndarray) -> bf.Letterbox:
        """Letterbox `bgr` (HxWx3 uint8) into the input tensor `x`; returns the mapping
        back to image pixels.

        The border is written only when the letterbox changes and has one (the
        tensor keeps it between calls); the picture goes BGR -> RGB -> [-1, 1]
        straight into the tensor rows, in one OpenCV pass where those rows are
        contiguous.
        """
        h, w = bgr.shape[:2]
        if self._letterbox is None or self._shape != (w, h):
            lb = bf.Letterbox.fit(w, h, self.spec.input_size)
            if lb.pad_x or lb.pad_y:
                x.fill(-1.0)
            self._letterbox, self._shape = lb, (w, h)
        lb = self._letterbox
        rw, rh = lb.resized_shape(w, h)
        if self.spec.resize == "linear":
            small = cv2.resize(bgr, (rw, rh), interpolation=cv2.INTER_LINEAR)
        else:
            small = shrink(bgr, rw, rh)
        rgb = cv2.cvtColor(small, cv2.COLOR_BGR2RGB)
        px, py = int(lb.pad_x), int(lb.pad_y)
        region = x[0, py:py + rh, px:px + rw]
        if region.flags.c_contiguous:  # no left/right border: 0.09 ms less than NumPy
            cv2.addWeighted(rgb, 1.0 / 127.5, rgb, 0.0, -1.0, dst=region, dtype=cv2.CV_32F)
        else:
            np.multiply(rgb, 1.0 / 127.5, out=region, casting="unsafe")
            region -= 1.0
        return lb

    def _crop_into(self, bgr: np.ndarray, cx: float, cy: float, side: float,
                   x: np.ndarray) -> bf.Letterbox:
        """The `side`-pixel square centred at (cx, cy) into the input tensor `x` (black
        where it leaves the image); returns the mapping from the input to *frame*
        pixels, so detections decode straight into the frame.

        Fed "linear": one `warpAffine` crops, scales and pads at once, sampling as
        `cv2.resize` does (pixel centres aligned), the way MediaPipe feeds its
        region-of-interest models; about half the time of crop + shrink on a
        tracked frame (0.1 vs 0.25 ms), same distances and jitter (measured with
        benchmarks/faces.py). Fed "area": crop, then `shrink`.
        """
        if self.spec.resize != "linear":
            crop, x0, y0 = crop_square(bgr, cx, cy, side)
            return self._letterbox_into(crop, x).moved(x0, y0)
        size = self.spec.input_size
        s = max(round(side), 2)
        x0, y0 = round(cx - s / 2), round(cy - s / 2)
        k = size / s
        # dst = (src - x0 + 0.5) * k - 0.5: pixel centres map as in cv2.resize.
        warp = np.array([[k, 0.0, (0.5 - x0) * k - 0.5], [0.0, k, (0.5 - y0) * k - 0.5]])
        small = cv2.warpAffine(bgr, warp, (size, size), flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
        self._letterbox = None  # the whole tensor is this crop now: no border kept
        rgb = cv2.cvtColor(small, cv2.COLOR_BGR2RGB)
        cv2.addWeighted(rgb, 1.0 / 127.5, rgb, 0.0, -1.0, dst=x[0], dtype=cv2.CV_32F)
        return bf.Letterbox(k, 0.0, 0.0, size).moved(x0, y0)

    def _detect_with(self, fill: Callable[[np.ndarray], bf.Letterbox], min_score: float,
                     max_faces: int) -> list[bf.Detection]:
        """prepare (`fill` the input) -> infer -> decode, each once, no tensor copied."""
        self.inferences += 1

        def decode(lb: bf.Letterbox, scores: np.ndarray, boxes: np.ndarray) -> list[bf.Detection]:
            return bf.postprocess(scores, boxes, self._anchors, self.spec, lb, min_score,
                                  max_faces)

        return self.model.infer(fill, decode)

    def input_tensor(self) -> np.ndarray:
        """What the network was last given (tests)."""
        return np.asarray(self.model.input_copy()[0], np.float32)

    def detect(self, bgr: np.ndarray, max_faces: int = 16) -> list[bf.Detection]:
        """All faces in a BGR image, best score first."""
        if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8 or bgr.size == 0:
            raise ValueError(f"expected an HxWx3 uint8 BGR image, got {bgr.shape} {bgr.dtype}")
        return self._detect_with(lambda x: self._letterbox_into(bgr, x), self.min_score,
                                 max_faces)

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
        side = context * max(det.width, det.height)
        for found in self._detect_with(lambda x: self._crop_into(bgr, cx, cy, side, x),
                                       min_score, 4):
            fcx, fcy = found.centre
            if abs(fcx - cx) < det.width / 2 and abs(fcy - cy) < det.height / 2:
                return found
        return None
