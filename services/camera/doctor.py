"""The camera's and the face detector's part of `buddybot doctor`: the device
opens, OpenCV and LiteRT are installed, frames come at the configured pace.

Nothing here imports OpenCV until a device is really opened, so doctor runs
(and says OpenCV is MISSING) where it is not installed.
"""

from __future__ import annotations

import os
from collections.abc import Callable

from buddybot.camera.settings import DEFAULT_FPS, CameraSettings
from buddybot.contract import keys
from buddybot.runtime.health import FAIL, OK, Check, DoctorHooks, Rate


def check_camera(source: str, sim: bool, in_use: bool = False,
                 opener: Callable[[str], bool] | None = None) -> Check:
    """The configured camera device opens (a file exists). Not in sim; not while the
    camera service holds it (`in_use`)."""
    if sim or not source:
        return Check("camera device", OK, "simulated (no camera needed)")
    if in_use:
        return Check("camera device", OK, f"{source}: held by the running camera service")
    if "://" in source:
        return Check("camera device", OK, f"{source}: network stream, not opened here")
    if not source.isdigit() and not source.startswith("/dev/") and "%" not in source:
        if os.path.exists(source):
            return Check("camera device", OK, f"{source}: file present")
        return Check("camera device", FAIL, f"{source} does not exist")
    opened = (opener or open_camera)(source)
    if opened:
        return Check("camera device", OK, f"{source} opens")
    return Check("camera device", FAIL, f"{source} cannot be opened (unplugged, or in use "
                 "by another program?)")


def open_camera(source: str) -> bool:
    """Open and release the capture the camera service would open for `source`."""
    try:
        from buddybot.camera.sources import CvSource, parse_source
    except ImportError:  # no OpenCV
        return False
    capture = CvSource(parse_source(source))
    try:
        return capture.open()
    finally:
        capture.release()


def _devices(settings: CameraSettings, sim: bool, in_use: bool) -> list[Check]:
    return [check_camera(settings.source, sim or settings.sim, in_use)]


def _rates(settings: CameraSettings | None, _sim: bool) -> list[Rate]:
    fps = settings.fps if settings is not None else None
    return [Rate("camera images", keys.CAMERA_IMAGE.wildcard(), fps or DEFAULT_FPS)]


CAPTURE = DoctorHooks(
    devices=_devices,
    packages=(("opencv", ("opencv-python-headless", "opencv-python",
                          "opencv-contrib-python")),),
    rates=_rates)
DETECTOR = DoctorHooks(packages=(("ai-edge-litert", ("ai-edge-litert",)),))
