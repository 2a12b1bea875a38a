"""The camera's doctor checks on crafted sources: no camera opened."""

from __future__ import annotations

from pathlib import Path

from buddybot.camera.doctor import CAPTURE, DETECTOR, check_camera
from buddybot.camera.settings import DEFAULT_FPS, CameraSettings
from buddybot.runtime.health import FAIL, OK


def test_camera_device(tmp_path: Path) -> None:
    assert check_camera("0", sim=True).level == OK
    assert check_camera("0", sim=False, in_use=True).level == OK
    assert check_camera("0", sim=False, opener=lambda _s: True).level == OK
    refused = check_camera("/dev/video9", sim=False, opener=lambda _s: False)
    assert refused.level == FAIL and "/dev/video9" in refused.detail
    assert check_camera("/no/such/clip.mp4", sim=False).level == FAIL
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"")
    assert check_camera(str(clip), sim=False).detail == f"{clip}: file present"
    assert "network stream" in check_camera("rtsp://cam.local/1", sim=False).detail


def test_a_device_that_is_not_there_does_not_open() -> None:
    """The real opener (OpenCV, as the camera service opens it) on a missing device."""
    check = check_camera("/dev/video-buddybot-none", sim=False)
    assert check.level == FAIL and "cannot be opened" in check.detail


def test_the_hooks_follow_the_settings() -> None:
    assert CAPTURE.devices is not None and CAPTURE.rates is not None
    [check] = CAPTURE.devices(CameraSettings(source="0", sim=True), False, False)
    assert check.level == OK and "simulated" in check.detail
    assert [r.hz for r in CAPTURE.rates(CameraSettings(fps=12.5), False)] == [12.5]
    assert [r.hz for r in CAPTURE.rates(CameraSettings(), False)] == [DEFAULT_FPS]
    assert [r.name for r in CAPTURE.rates(None, True)] == ["camera images"]
    assert [name for name, _ in CAPTURE.packages + DETECTOR.packages] == [
        "opencv", "ai-edge-litert"]
