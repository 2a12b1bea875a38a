"""Config tables `[camera]` and `[face_detector]` (pure msgspec structs).

Every field has a default, so an empty config runs the simulated robot;
command-line options override these values. See docs/camera.md.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from buddybot.contract.messages import MAX_SIDE

DEFAULT_FPS = 30.0
"""The camera's pace when `fps` is not set and the source says none (the simulation's,
most webcams')."""


class CameraSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    name: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64,
        description="camera name in keys: frames go to camera/<name>/image")] = "front"
    source: Annotated[str, msgspec.Meta(
        description="device index, video file, URL or image-sequence pattern such as "
        "frames/%04d.png; empty = simulation under `up`")] = ""
    sim: Annotated[bool, msgspec.Meta(
        description="simulated camera: films the simulated world of [sim] (real face "
        "photos where its people are)")] = False
    fps: Annotated[float, msgspec.Meta(
        gt=0.0, le=1000.0,
        description="frames per second of files, sequences and the simulation")] | None = None
    """Pacing of files, sequences and the simulation (default: the file's own fps, else 30)."""
    width: Annotated[int, msgspec.Meta(
        ge=1, le=MAX_SIDE,
        description="frame width in pixels")] | None = None
    """Requested resolution (devices) / resize target (other sources); sim default 640x480."""
    height: Annotated[int, msgspec.Meta(
        ge=1, le=MAX_SIDE,
        description="frame height in pixels")] | None = None
    encoding: Annotated[Literal["bgr8", "jpeg"], msgspec.Meta(
        description="wire encoding of the frames")] = "bgr8"
    """bgr8 for same-host consumers (no codec cost); jpeg for remote hosts (~20x smaller)."""
    jpeg_quality: Annotated[int, msgspec.Meta(
        ge=1, le=100,
        description="JPEG quality of `encoding = jpeg` frames (higher: bigger, sharper)")] = 85
    loop: Annotated[bool, msgspec.Meta(
        description="start a file or sequence over at its end")] = False
    """Restart a file or sequence at its end instead of ending the service."""
    frame_id: str = ""
    """Coordinate frame name in messages; empty = camera_<name>."""
    reopen_initial_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0,
        description="seconds before the first reopen after the camera failed; doubles up to "
        "reopen_max_s")] = 0.5
    reopen_max_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0,
        description="longest wait between reopen attempts, seconds")] = 10.0


class FaceDetectorSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    camera: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64, description="camera name whose images are read")] = "front"
    face_width_m: Annotated[float, msgspec.Meta(
        extra={"live": True},
        gt=0.0, le=1.0,
        description="real face width in metres: the main distance cue")] = 0.15
    """Real width of the face box on an average adult (the width cue's W); calibrated for
    short-range boxes, which `refine` measures with."""
    fx: Annotated[float, msgspec.Meta(
        gt=0.0, le=1e6,
        description="focal length x, pixels")] | None = 600.0
    fy: Annotated[float, msgspec.Meta(
        gt=0.0, le=1e6,
        description="focal length y, pixels")] | None = 600.0
    cx: Annotated[float, msgspec.Meta(
        ge=0.0, le=MAX_SIDE,
        description="principal point x, pixels (default: image centre)")] | None = None
    cy: Annotated[float, msgspec.Meta(
        ge=0.0, le=MAX_SIDE,
        description="principal point y, pixels (default: image centre)")] | None = None
    hfov_deg: Annotated[float, msgspec.Meta(
        gt=0.0, lt=180.0,
        description="horizontal field of view in degrees; when set it defines fx")] | None = None
    """Horizontal field of view; when set it defines fx (and fy unless given)."""
    model: Annotated[Literal["full_sparse", "full", "short"], msgspec.Meta(
        description="BlazeFace model: full_sparse (to ~4 m, MediaPipe's own choice: "
        "fastest, best on small faces), full (dense, to ~4 m) or short (to ~2 m)")] = (
        "full_sparse")
    """Whole-frame detector. The sparse full-range network finds faces down to ~30 px
    (3.5 m) where the dense one stops at ~40 px, and runs a little faster on LiteRT."""
    model_path: Annotated[str, msgspec.Meta(
        description="explicit .tflite model file (empty: the packaged one)")] | None = None
    refine: Annotated[bool, msgspec.Meta(
        description="measure the followed face again with the short-range model")] = True
    """Re-detect the followed face with the short-range model in a crop 3 face-widths
    wide: far faces get a precise size and eye keypoints (one short-range inference on
    the crop, 0.66 ms at `refine_input_px` 96)."""
    refine_input_px: Annotated[int, msgspec.Meta(
        ge=64, le=128, multiple_of=16,
        description="input size in pixels of the short-range network on the followed "
        "face's crop (128: its native size; smaller is faster)")] = 96
    """The crop of the followed face (tracking and refinement) is fed to the short-range
    network at this size; the network is fully convolutional and runs on smaller anchor
    grids (12x12 and 6x6 at 96). The face fills a third of the crop either way. Measured
    (docs/camera.md): inference 1.17 -> 0.86 ms at 112 and 0.66 ms at 96; mean distance
    error on the composed photos 2.9% at 128, 3.5% at 112, 3.7% at 96; unsmoothed
    distance jitter 1.30%, 1.64%, 1.48% of the distance. 96 is what keeps the service
    path under 2 ms; 128 is the most precise."""
    min_score: Annotated[float, msgspec.Meta(
        extra={"live": True},
        gt=0.0, lt=1.0,
        description="detection score threshold (default: the model's own)")] | None = None
    """Detection threshold; default the model's MediaPipe value (full 0.6, short 0.5)."""
    eye_distance_m: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=0.2,
        description="inter-pupillary distance in metres: second distance cue, "
        "0 disables it")] = 0.063
    """Adult mean inter-pupillary distance: second distance cue; 0 disables it."""
    smoothing: Annotated[bool, msgspec.Meta(
        extra={"live": True},
        description="smooth positions with a One-Euro filter (off: raw positions)")] = True
    min_cutoff_hz: Annotated[float, msgspec.Meta(
        extra={"live": True},
        gt=0.0, le=1000.0,
        description="One-Euro filter cut-off in Hz for a still face")] = 1.0
    """One-Euro filter: cut-off for a still face (lower = steadier, more lag)."""
    beta: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=1000.0,
        description="One-Euro filter speed coefficient, per m/s")] = 2.0
    """One-Euro filter: how fast the cut-off rises with speed (per m/s)."""
    switch_after_s: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=3600.0,
        description="seconds the followed face must be gone before another is taken")] = 0.5
    """How long the followed face must be gone before another face is taken."""
    full_every_s: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=3600.0,
        description="seconds between whole-frame detections (0: every frame)")] = 0.25
    """Between whole-frame detections, follow the tracked face by re-detecting it only in
    its crop (the short-range refiner: ~1.4 ms for the whole tracked frame instead of a
    ~4.5 ms whole-frame pass plus the refinement, on LiteRT). A crop result that no
    head movement could explain is refused by the tracking gate and the frame searched
    whole. A new or larger face is still noticed at the next whole-frame pass, at most
    this late. 0: the whole frame every time. Needs `refine`."""
    defer_after_ms: Annotated[float, msgspec.Meta(
        extra={"live": True},
        ge=0.0, le=100.0,
        description="milliseconds between publishing a face and starting the work put "
        "off until then (whole-frame pass, iris)")] = 3.0
    """The whole-frame pass (~4.5 ms) and the iris (~6 ms) run after the face is
    published; started at once they take a core while the face is still on its way
    through the router, the controller and the eyes driver. Waiting this long first let
    it arrive: on the whole robot (2 cores) the gaze latency's p95 fell from ~10 ms to
    ~6 ms, the median from 4.8 to 4.6 ms (benchmarks/robot.py). 0: start at once."""
    debug_jpeg_quality: Annotated[int, msgspec.Meta(
        extra={"live": True},
        ge=1, le=100,
        description="JPEG quality of the debug image")] = 80
    max_pixels: Annotated[int, msgspec.Meta(
        extra={"live": True},
        ge=1, le=MAX_SIDE * MAX_SIDE,
        description="largest frame accepted, pixels (width*height)")] = 3840 * 2160
    """Largest frame accepted (width*height, checked on the JPEG header before decoding).
    4K UHD, the largest mode of common USB and IP cameras: decoding one raised peak memory
    by 54 MB (baseline) / 73 MB (progressive, 4:4:4), measured. The network sees 192x192, so
    bigger frames only cost memory and time; a forged header claiming 20000x20000 took
    2.4 GB. Range 1..16384*16384 (the Image message's own limit)."""
    iris: Annotated[bool, msgspec.Meta(
        description="measure the iris close up (face mesh + iris models) as a third "
        "distance cue")] = True
    """The iris stage (~6 ms, three inferences) runs after the face is published, only
    for a face big enough and at most every `iris_every_s`; what it learns about the
    person is held in between (see docs/camera.md, "Iris distance")."""
    iris_every_s: Annotated[float, msgspec.Meta(
        ge=0.05, le=60.0,
        description="seconds between iris measurements of the followed face")] = 0.5
    iris_min_px: Annotated[float, msgspec.Meta(
        ge=2.0, le=100.0,
        description="smallest expected iris diameter, pixels, worth measuring and using "
        "(below ~6 px the model reads it 4-13% small)")] = 6.0
    threads: Annotated[int, msgspec.Meta(
        ge=1, le=64,
        description="LiteRT and OpenCV threads (1 leaves a core to the rest)")] = 1
    """Threads for LiteRT inference and OpenCV resizing: 1 leaves the other core to
    capture and the rest of the robot on a 2-core computer (what the benchmark measures)."""
