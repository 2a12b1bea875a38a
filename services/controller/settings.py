"""Config table `[controller]` (pure msgspec structs)."""

from __future__ import annotations

import msgspec


class CameraToEyes(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Static transform: camera origin and orientation in the eyes-centre frame."""

    translation_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)


class ControllerSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    camera: str = "front"
    camera_to_eyes: CameraToEyes = msgspec.field(default_factory=CameraToEyes)
