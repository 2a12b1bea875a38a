"""`buddybot run face-detector`: camera frames -> face position.

Thin adapter around `pipeline.FacePipeline`; each frame goes one way:
decode -> decide (`process(defer=True)`) -> publish -> run the owed work
(whole-frame pass, iris) after `defer_after_ms`. Frames arrive through a
latest-value slot (`delivery="latest"`): inference always runs on the
newest frame and stale ones are dropped, never queued. The face message
keeps the image's `stamp_ns` and `frame_id`. Every processed frame also
gives one `camera/<cam>/faces` (`detections.to_message`: every box in
pixels, for viewers), put after the face so the gaze never waits for it.
The debug image is rendered and JPEG-encoded only while someone
subscribes to it (Zenoh matching status), so it costs nothing otherwise.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence

import cv2
import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera import detections, draw, models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.iris import IrisNet
from buddybot.camera.litert import ModelLoadError
from buddybot.camera.pipeline import FacePipeline, FaceResult, Owed
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.contract import images, jpeg, keys
from buddybot.contract import messages as m
from buddybot.runtime.config import resolve_path
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.limits import clip, plausible_stamp
from buddybot.runtime.node import RateLimitedLog
from buddybot.runtime.overrides import given, merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Every option overrides a `[face_detector]` key (defaults and ranges: settings.py)."""
    def option(flag: str, field: str,
               action: type[argparse.Action] | None = None) -> None:
        settings_option(parser, flag, struct=FaceDetectorSettings, field=field, action=action)

    option("--camera", "camera")
    option("--model", "model")
    option("--model-path", "model_path")
    for name in ("fx", "fy", "cx", "cy", "hfov_deg", "face_width_m", "min_score"):
        option("--" + name.replace("_", "-"), name)
    # Both spellings: `--smoothing`/`--no-smoothing`, `--refine`/`--no-refine`.
    option("--smoothing", "smoothing", action=argparse.BooleanOptionalAction)
    option("--refine", "refine", action=argparse.BooleanOptionalAction)
    option("--max-pixels", "max_pixels")


def settings_from(ctx: ServiceContext) -> FaceDetectorSettings:
    """`[face_detector]` with the command line on top: what `run` detects with.

    Ranges are checked by `merge` (and the file by `parse_config`); what is
    left here are the rules that span fields or keys.
    """
    merged = merge(ctx.config.section(FaceDetectorSettings), ctx.args)
    problems = []
    if not keys.valid_robot_id(merged.camera):
        problems.append(f"camera {merged.camera!r} is not a valid name")
    if merged.hfov_deg is None and merged.fx is None:
        problems.append("fx must be set (or set hfov_deg)")
    if problems:
        raise ConfigError("face_detector: " + "; ".join(problems))
    return merged


def load_nets(ctx: ServiceContext, s: FaceDetectorSettings) -> tuple[FaceNet, FaceNet | None]:
    """The detector model, and the short-range refiner (None when refine is off)."""
    net = load_net(ctx, s)
    return net, load_refiner(net, s)


def load_refiner(net: FaceNet, s: FaceDetectorSettings) -> FaceNet | None:
    """The short-range network at `refine_input_px` for the followed face's crop (the
    whole-frame `net` itself when that is the short model at that size), or None
    when refine is off."""
    if not s.refine:
        return None
    if net.spec.name == "short" and net.spec.input_size == s.refine_input_px:
        return net
    try:
        return FaceNet(models.locate("short"), bf.SHORT_RANGE, num_threads=s.threads,
                       input_size=s.refine_input_px)
    except (models.ModelNotFound, ModelLoadError) as exc:
        raise ConfigError(f"refine needs the short-range model: {exc}") from None


def load_net(ctx: ServiceContext, s: FaceDetectorSettings) -> FaceNet:
    """The whole-frame model: `model_path` when set (checked to have `model`'s tensor
    layout), else the packaged file of `model`. Any failure is a ConfigError naming
    the file: the service exits 2."""
    explicit = None
    if s.model_path:
        explicit = resolve_path(ctx.config, s.model_path,
                                from_command_line=given(ctx.args, FaceDetectorSettings,
                                                        "model_path"))
    try:
        path = models.locate(s.model, explicit)
        return FaceNet(path, bf.SPECS[s.model], s.min_score, num_threads=s.threads)
    except (models.ModelNotFound, ModelLoadError) as exc:
        raise ConfigError(str(exc)) from None


def build(ctx: ServiceContext) -> tuple[FaceDetectorSettings, FacePipeline]:
    """Settings and the pipeline exactly as `run` uses them (tests check every key
    through this, so a key the wiring leaves out shows up as a failing test)."""
    settings = settings_from(ctx)
    cv2.setNumThreads(settings.threads)
    net, refiner = load_nets(ctx, settings)
    return settings, FacePipeline(net, settings, refiner, irises=load_irises(settings),
                                  first_track=first_track(time.time()))


TRACKS_PER_S = 100
"""More new persons per second than a camera has frames: track ids counted from
`TRACKS_PER_S` x the start time never meet those of an earlier run."""


def first_track(now_s: float) -> int:
    """The first track id of a detector started at `now_s` (wall clock, s)."""
    return max(1, int(now_s * TRACKS_PER_S))


def load_irises(s: FaceDetectorSettings) -> IrisNet | None:
    """The face-mesh and iris models when `iris` is on; a missing or wrong file is a
    ConfigError naming it (exit 2)."""
    if not s.iris:
        return None
    try:
        return IrisNet(num_threads=s.threads)
    except (models.ModelNotFound, ModelLoadError) as exc:
        raise ConfigError(f"iris (set iris = false to run without): {exc}") from None


def after_publishing(pipeline: FacePipeline, owed: Sequence[Owed], delay_s: float,
                     wait: Callable[[float], object]) -> list[bf.Detection] | None:
    """Run the work `process(defer=True)` owed once the face is published: the
    whole-frame pass and the iris, when due (the pass's faces, or None).

    It first waits `delay_s` (`wait`: the node's stop event, so shutdown is not held
    up): started at once, this work takes a core while the face is still on its way
    to the eyes (see `defer_after_ms`). With nothing owed there is no wait.
    """
    if not owed:
        return None
    if delay_s > 0:
        wait(delay_s)
    return pipeline.run_owed(owed)


def run(ctx: ServiceContext) -> int:
    settings, pipeline = build(ctx)
    # A live change waits here for the frame thread, which applies it between frames:
    # a frame is never processed half with the old settings, half with the new.
    pending: list[FaceDetectorSettings] = []
    net = pipeline.net
    node = ctx.node()
    log = node.log
    warn = RateLimitedLog(log)
    diag = node.diagnostics
    diag.values.update({"model": settings.model, "frames": 0, "faces": 0, "bad_frames": 0,
                        "too_large": 0, "infer_ms": 0.0, "latency_ms": 0.0})
    face_pub = node.publisher(keys.FACE, camera=settings.camera)
    faces_pub = node.publisher(keys.FACES, camera=settings.camera)
    bystanders = detections.Bystanders()
    debug_pub = node.publisher(keys.DEBUG_IMAGE, camera=settings.camera)
    log.info("face detector: %s model %s on LiteRT", settings.model, net.path)

    def decode(img: m.Image) -> np.ndarray | None:
        """The frame as BGR, or None when refused (counted and logged)."""
        try:
            return images.decode_image(img, settings.max_pixels)
        except images.FrameRefused as refused:
            diag.increment(refused.reason)
            warn.warning(f"refused:{refused.reason}", "dropped image from %s: %s",
                         clip(img.frame_id, 60), refused.text)
            return None

    def stamp_of(img: m.Image) -> int:
        """The image's stamp, or the arrival time when it is not plausible.

        One wrong clock must not hold back every later frame (tracking and
        smoothing order by stamp) nor reach the controller. The node runtime
        does the same on arrival (same counter); this keeps the detector safe
        on its own.
        """
        stamp_ns, replaced = plausible_stamp(img.stamp_ns, m.now_ns())
        if replaced:
            diag.increment("stamps replaced")
            warn.warning("stamp", "image stamp %d is not plausible (now %d): using the "
                         "arrival time", img.stamp_ns, stamp_ns)
        return stamp_ns

    def publish(img: m.Image, bgr: np.ndarray, stamp_ns: int, result: FaceResult) -> None:
        """The face first (the gaze's latency path), then every box of the frame,
        also when there is no face (viewers clear their boxes)."""
        if result.point is not None and result.target is not None:
            x, y, z = result.point
            face_pub.put(m.FacePosition(
                stamp_ns=stamp_ns, frame_id=img.frame_id, point=m.Point(x=x, y=y, z=z),
                confidence=min(max(result.target.score, 0.0), 1.0),
                track=result.track or None,
            ))
            diag.increment("faces")
        diag.values["latency_ms"] = round((m.now_ns() - stamp_ns) / 1e6, 1)
        faces_pub.put(detections.to_message(
            result, stamp_ns, img.frame_id, bgr.shape[1], bgr.shape[0],
            bystanders.current(result, stamp_ns, 2 * settings.full_every_s + 0.1)))

    def publish_debug(img: m.Image, bgr: np.ndarray, stamp_ns: int, result: FaceResult,
                      faces: list[bf.Detection]) -> None:
        data = jpeg.encode(
            draw.render(bgr, faces, result.target, result.estimate, result.measured),
            settings.debug_jpeg_quality,
        )
        if data is not None:
            debug_pub.put(m.Image(stamp_ns=stamp_ns, frame_id=img.frame_id,
                                  width=bgr.shape[1], height=bgr.shape[0], encoding="jpeg",
                                  data=data))
            diag.increment("debug_images")

    def on_image(img: m.Image, _key: str) -> None:
        nonlocal settings
        if pending:
            settings = pending.pop()
            pending.clear()
            pipeline.reconfigure(settings)
        bgr = decode(img)
        if bgr is None:
            return
        stamp_ns = stamp_of(img)
        t0 = time.perf_counter()
        result = pipeline.process(bgr, stamp_ns, defer=True)
        if result.refused is not None:
            diag.increment(result.refused)
            warn.warning(f"refused:{result.refused}", "dropped frame %dx%d from %s",
                         bgr.shape[1], bgr.shape[0], clip(img.frame_id, 60))
            return
        diag.increment("frames")
        if diag.level != "OK" or diag.message.startswith("waiting"):
            diag.set("OK", "detecting")
        diag.values["infer_ms"] = round((time.perf_counter() - t0) * 1000, 1)
        publish(img, bgr, stamp_ns, result)
        diag.values["target_changes"] = pipeline.tracker.target_changes
        if pipeline.gate_rejections:
            diag.values["track_rejected"] = sum(pipeline.gate_rejections.values())
        searched = after_publishing(pipeline, result.owed, settings.defer_after_ms / 1000.0,
                                    node.stop_event.wait)
        if searched is not None:
            bystanders.update(searched, result, stamp_ns)
        if result.estimate is not None and result.estimate.fusion is not None:
            diag.values.update(result.estimate.fusion.as_dict())  # type: ignore[arg-type]
        if pipeline.irises is not None:
            diag.values["iris_measurements"] = pipeline.iris_measurements
            diag.values["iris_accepted"] = pipeline.iris_accepted
        if debug_pub.has_subscribers():
            publish_debug(img, bgr, stamp_ns, result,
                          result.faces if searched is None else searched)

    try:
        LiveSettings(settings, pending.append).serve(node)
        node.subscribe(keys.CAMERA_IMAGE, on_image, delivery="latest", camera=settings.camera)
        diag.set("OK", f"waiting for camera/{settings.camera}/image")
        node.spin()
    finally:
        node.close()
    return 0
