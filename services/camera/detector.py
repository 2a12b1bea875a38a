"""`buddybot run face-detector`: camera frames -> face position (the seed's camera_hld).

Thin adapter around `pipeline.FacePipeline`. Frames arrive through a
latest-value slot (`delivery="latest"`): inference always runs on the
newest frame and stale ones are dropped, never queued. The face message
keeps the image's `stamp_ns` and `frame_id`. The debug image is rendered
and JPEG-encoded only while someone subscribes to it (Zenoh matching
status), so it costs nothing otherwise.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import cv2

from buddybot.camera import blazeface as bf
from buddybot.camera import draw, frames, models
from buddybot.camera.facenet import FaceNet, ModelLoadError
from buddybot.camera.pipeline import FacePipeline
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.config import resolve_path
from buddybot.core.errors import ConfigError
from buddybot.core.limits import clip, plausible_stamp
from buddybot.core.node import RateLimitedLog
from buddybot.core.service import ServiceContext


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--camera", help="camera name (default 'front')")
    parser.add_argument("--model", choices=["full", "short"],
                        help="BlazeFace full range (to ~4 m, default) or short range (to ~2 m)")
    parser.add_argument("--model-path", help="explicit .tflite file")
    parser.add_argument("--fx", type=float, help="focal length x (pixels)")
    parser.add_argument("--fy", type=float, help="focal length y (pixels)")
    parser.add_argument("--cx", type=float, help="principal point x (default image centre)")
    parser.add_argument("--cy", type=float, help="principal point y (default image centre)")
    parser.add_argument("--hfov-deg", type=float, help="horizontal field of view (sets fx)")
    parser.add_argument("--face-width-m", type=float, help="real face width (m)")
    parser.add_argument("--min-score", type=float, help="detection threshold 0..1")
    parser.add_argument("--no-smoothing", action="store_true", help="publish raw positions")
    parser.add_argument("--no-refine", action="store_true",
                        help="measure the face on the whole-frame detection only")
    parser.add_argument("--max-pixels", type=int,
                        help="refuse larger frames, before decoding (default 3840*2160)")


def pick(cli: object, cfg: object) -> Any:
    """The command-line value when given, else the config's."""
    return cfg if cli is None else cli


def effective_settings(ctx: ServiceContext) -> FaceDetectorSettings:
    s = ctx.config.face_detector
    a = ctx.args
    merged = FaceDetectorSettings(
        camera=a.camera or s.camera, face_width_m=pick(a.face_width_m, s.face_width_m),
        fx=pick(a.fx, s.fx), fy=pick(a.fy, s.fy), cx=pick(a.cx, s.cx), cy=pick(a.cy, s.cy),
        hfov_deg=pick(a.hfov_deg, s.hfov_deg), model=a.model or s.model,
        model_path=pick(a.model_path, s.model_path), min_score=pick(a.min_score, s.min_score),
        eye_distance_m=s.eye_distance_m, smoothing=s.smoothing and not a.no_smoothing,
        refine=s.refine and not a.no_refine, min_cutoff_hz=s.min_cutoff_hz, beta=s.beta,
        switch_after_s=s.switch_after_s, full_every_s=s.full_every_s,
        debug_jpeg_quality=s.debug_jpeg_quality, threads=s.threads,
        max_pixels=pick(a.max_pixels, s.max_pixels),
    )
    problems = []
    if not keys.valid_robot_id(merged.camera):
        problems.append(f"camera {merged.camera!r} is not a valid name")
    if merged.face_width_m <= 0:
        problems.append("face_width_m must be positive")
    if merged.hfov_deg is None and (merged.fx is None or merged.fx <= 0):
        problems.append("fx must be positive (or set hfov_deg)")
    if merged.min_score is not None and not 0 < merged.min_score < 1:
        problems.append("min_score must be in (0, 1)")
    if merged.eye_distance_m < 0:
        problems.append("eye_distance_m must be >= 0")
    if merged.min_cutoff_hz <= 0 or merged.beta < 0:
        problems.append("min_cutoff_hz must be > 0 and beta >= 0")
    if not 1 <= merged.threads <= 64:
        problems.append("threads must be in 1..64")
    if merged.switch_after_s < 0:
        problems.append("switch_after_s must be >= 0")
    if not 1 <= merged.debug_jpeg_quality <= 100:
        problems.append("debug_jpeg_quality must be in 1..100")
    if merged.full_every_s < 0:
        problems.append("full_every_s must be >= 0")
    if not 1 <= merged.max_pixels <= frames.MAX_SIDE ** 2:
        problems.append(f"max_pixels must be in 1..{frames.MAX_SIDE ** 2}")
    if problems:
        raise ConfigError("face_detector: " + "; ".join(problems))
    return merged


def load_nets(ctx: ServiceContext, s: FaceDetectorSettings) -> tuple[FaceNet, FaceNet | None]:
    """The detector model, and the short-range refiner (None when refine is off)."""
    net = load_net(ctx, s)
    if not s.refine:
        return net, None
    if s.model == "short":
        return net, net
    try:
        return net, FaceNet(models.locate("short"), bf.SHORT_RANGE)
    except (models.ModelNotFound, ModelLoadError) as exc:
        raise ConfigError(f"refine needs the short-range model: {exc}") from None


def load_net(ctx: ServiceContext, s: FaceDetectorSettings) -> FaceNet:
    explicit = None
    if s.model_path:
        explicit = resolve_path(ctx.config, s.model_path,
                                from_command_line=ctx.args.model_path is not None)
    try:
        path = models.locate(s.model, explicit)
        return FaceNet(path, bf.SPECS[s.model], s.min_score)
    except (models.ModelNotFound, ModelLoadError) as exc:
        raise ConfigError(str(exc)) from None


def run(ctx: ServiceContext) -> int:
    settings = effective_settings(ctx)
    cv2.setNumThreads(settings.threads)
    net, refiner = load_nets(ctx, settings)
    pipeline = FacePipeline(net, settings, refiner)
    node = ctx.node()
    log = node.log
    warn = RateLimitedLog(log)
    diag = node.diagnostics
    diag.values.update({"model": settings.model, "frames": 0, "faces": 0, "bad_frames": 0,
                        "too_large": 0, "infer_ms": 0.0, "latency_ms": 0.0})
    face_pub = node.publisher(keys.FACE, camera=settings.camera)
    debug_pub = node.publisher(keys.DEBUG_IMAGE, camera=settings.camera)
    log.info("face detector: %s-range model %s", settings.model, net.path)

    def on_image(img: m.Image, _key: str) -> None:
        try:
            bgr = frames.decode_image(img, settings.max_pixels)
        except frames.FrameRefused as refused:
            diag.increment(refused.reason)
            warn.warning(f"refused:{refused.reason}", "dropped image from %s: %s",
                         clip(img.frame_id, 60), refused.text)
            return
        # One wrong clock must not hold back every later frame (tracking and
        # smoothing order by stamp) nor reach the controller: such a stamp
        # becomes the arrival time. The node runtime does the same on arrival
        # (same counter); this keeps the detector safe on its own.
        stamp_ns, replaced = plausible_stamp(img.stamp_ns, m.now_ns())
        if replaced:
            diag.increment("stamps replaced")
            warn.warning("stamp", "image stamp %d is not plausible (now %d): using the "
                         "arrival time", img.stamp_ns, stamp_ns)
        t0 = time.perf_counter()
        result = pipeline.process(bgr, stamp_ns, defer_search=True)
        diag.increment("frames")
        if diag.level != "OK" or diag.message.startswith("waiting"):
            diag.set("OK", "detecting")
        diag.values["infer_ms"] = round((time.perf_counter() - t0) * 1000, 1)
        if result.point is not None and result.target is not None:
            x, y, z = result.point
            face_pub.put(m.FacePosition(
                stamp_ns=stamp_ns, frame_id=img.frame_id, point=m.Point(x=x, y=y, z=z),
                confidence=min(max(result.target.score, 0.0), 1.0),
            ))
            diag.increment("faces")
        diag.values["latency_ms"] = round((m.now_ns() - stamp_ns) / 1e6, 1)
        diag.values["target_changes"] = pipeline.tracker.target_changes
        # The whole-frame pass, when due, runs after the face is out (off the latency path).
        searched = pipeline.search_if_due(bgr, stamp_ns)
        if debug_pub.has_subscribers():
            faces = result.faces if searched is None else searched
            jpeg = draw.encode_jpeg(
                draw.render(bgr, faces, result.target, result.estimate, result.measured),
                settings.debug_jpeg_quality,
            )
            if jpeg is not None:
                debug_pub.put(m.Image(stamp_ns=stamp_ns, frame_id=img.frame_id,
                                      width=bgr.shape[1], height=bgr.shape[0], encoding="jpeg",
                                      data=jpeg))
                diag.increment("debug_images")

    try:
        node.subscribe(keys.CAMERA_IMAGE, on_image, delivery="latest", camera=settings.camera)
        diag.set("OK", f"waiting for camera/{settings.camera}/image")
        node.spin()
    finally:
        node.close()
    return 0
