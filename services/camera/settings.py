"""Config tables `[camera]` and `[face_detector]` (pure msgspec structs).

Every field has a default, so an empty config runs the simulated robot;
command-line options override these values. See docs/camera.md.
"""

from __future__ import annotations

from typing import Literal

import msgspec


class CameraSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    name: str = "front"
    """Key parameter: frames go to camera/<name>/image."""
    source: str = ""
    """Device index, video file, URL or image-sequence pattern; empty = simulation under `up`."""
    sim: bool = False
    fps: float | None = None
    """Pacing of files, sequences and the simulation (default: the file's own fps, else 30)."""
    width: int | None = None
    """Requested resolution (devices) / resize target (other sources); sim default 640x480."""
    height: int | None = None
    encoding: Literal["bgr8", "jpeg"] = "bgr8"
    """bgr8 for same-host consumers (no codec cost); jpeg for remote hosts (~20x smaller)."""
    jpeg_quality: int = 85
    loop: bool = False
    """Restart a file or sequence at its end instead of ending the service."""
    frame_id: str = ""
    """Coordinate frame name in messages; empty = camera_<name>."""
    reopen_initial_s: float = 0.5
    """First retry delay after the camera failed; doubles up to reopen_max_s."""
    reopen_max_s: float = 10.0


class FaceDetectorSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    camera: str = "front"
    face_width_m: float = 0.15
    """Real width of the face box on an average adult (seed: face width); calibrated for
    short-range boxes, which `refine` measures with."""
    fx: float | None = 600.0
    fy: float | None = 600.0
    cx: float | None = None
    cy: float | None = None
    hfov_deg: float | None = None
    """Horizontal field of view; when set it defines fx (and fy unless given)."""
    model: Literal["full", "short"] = "full"
    model_path: str | None = None
    refine: bool = True
    """Re-detect the followed face with the short-range model in a crop 3 face-widths
    wide: far faces get a precise size and eye keypoints (+~3 ms per frame)."""
    min_score: float | None = None
    """Detection threshold; default the model's MediaPipe value (full 0.6, short 0.5)."""
    eye_distance_m: float = 0.063
    """Adult mean inter-pupillary distance: second distance cue; 0 disables it."""
    smoothing: bool = True
    min_cutoff_hz: float = 1.0
    """One-Euro filter: cut-off for a still face (lower = steadier, more lag)."""
    beta: float = 2.0
    """One-Euro filter: how fast the cut-off rises with speed (per m/s)."""
    switch_after_s: float = 0.5
    """How long the followed face must be gone before another face is taken."""
    full_every_s: float = 0.25
    """Between whole-frame detections, follow the tracked face by re-detecting it only in
    its crop (the refiner, ~4 ms instead of ~17 ms a frame): gaze latency drops to a third.
    A new or larger face is still noticed at the next whole-frame pass, at most this late.
    0: the whole frame every time. Needs `refine`."""
    debug_jpeg_quality: int = 80
    max_pixels: int = 3840 * 2160
    """Largest frame accepted (width*height, checked on the JPEG header before decoding).
    4K UHD, the largest mode of common USB and IP cameras: decoding one raised peak memory
    by 54 MB (baseline) / 73 MB (progressive, 4:4:4), measured. The network sees 192x192, so
    bigger frames only cost memory and time; a forged header claiming 20000x20000 took
    2.4 GB. Range 1..16384*16384 (the Image message's own limit)."""
    threads: int = 1
    """OpenCV threads for inference: 1 leaves the other core to capture and the rest of
    the robot on a 2-core computer (and is what the benchmark measures)."""
