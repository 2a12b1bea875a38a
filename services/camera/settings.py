"""Config tables `[camera]` and `[face_detector]` (pure msgspec structs)."""

from __future__ import annotations

from typing import Literal

import msgspec


class CameraSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    name: str = "front"
    source: str = ""
    sim: bool = False
    fps: float | None = None
    width: int | None = None
    height: int | None = None
    encoding: Literal["bgr8", "jpeg"] = "bgr8"


class FaceDetectorSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    camera: str = "front"
    face_width_m: float = 0.15
    fx: float | None = 600.0
    fy: float | None = 600.0
    cx: float | None = None
    cy: float | None = None
    hfov_deg: float | None = None
    model: Literal["full", "short"] = "full"
    model_path: str | None = None
