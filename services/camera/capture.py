"""`buddybot run camera`: capture frames and publish them.

A thin adapter: the source (`sources.py`) gives frames, this loop stamps
them with the capture time and puts them on `camera/<name>/image` as raw
BGR (same host) or JPEG (remote hosts). The image topic uses congestion
control DROP, so a slow subscriber never stalls capture. A source that
fails to open or stops delivering is reopened with exponential backoff
and reported in diagnostics; the end of a file ends the service cleanly
(exit 0) or starts it over with `--loop`.
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from buddybot.camera import frames
from buddybot.camera.geometry import Intrinsics
from buddybot.camera.settings import DEFAULT_FPS, CameraSettings, FaceDetectorSettings
from buddybot.camera.sources import (
    FrameSource,
    SimSource,
    SourceSpec,
    make_source,
    parse_source,
)
from buddybot.contract import jpeg, keys
from buddybot.contract import messages as m
from buddybot.runtime.backoff import Backoff
from buddybot.runtime.config import resolve_path
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node, Publisher, RateLimitedLog
from buddybot.runtime.overrides import given, merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.rates import RateCounter
from buddybot.runtime.service import ServiceContext
from buddybot.sim.options import add_world_arguments, world_from
from buddybot.sim.views import Lens

MESSAGE_OVERHEAD = 256
"""Bytes of an Image message besides data and frame_id (MessagePack field names, numbers)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Every option overrides a `[camera]` key (defaults and ranges: settings.py)."""
    def option(flag: str, field: str,
               action: type[argparse.Action] | None = None) -> None:
        settings_option(parser, flag, struct=CameraSettings, field=field, action=action)

    option("--source", "source")
    option("--sim", "sim", action=argparse.BooleanOptionalAction)
    option("--camera", "name")
    option("--fps", "fps")
    option("--width", "width")
    option("--height", "height")
    option("--encoding", "encoding")
    option("--jpeg-quality", "jpeg_quality")
    option("--loop", "loop", action=argparse.BooleanOptionalAction)
    add_world_arguments(parser)


def settings_from(ctx: ServiceContext) -> CameraSettings:
    """`[camera]` with the command line on top (ranges checked by `merge`): what `run`
    captures with. The name becomes a key chunk, so it is checked here too."""
    merged = merge(ctx.config.section(CameraSettings), ctx.args)
    if not keys.valid_robot_id(merged.name):
        raise ConfigError(f"camera name {merged.name!r}: use letters, digits, '-' or '_'")
    return merged


class Capture:
    """The capture loop: open, read, stamp, encode, publish; reopen on failure."""

    def __init__(self, node: Node, settings: CameraSettings, spec: SourceSpec,
                 source: FrameSource) -> None:
        self.node = node
        self.s = settings
        self.spec = spec
        self.source = source
        self.frame_id = settings.frame_id or f"camera_{settings.name}"
        self.pub: Publisher[m.Image] = node.publisher(keys.CAMERA_IMAGE, camera=settings.name)
        self.backoff = Backoff(settings.reopen_initial_s, settings.reopen_max_s)
        self.diag = node.diagnostics
        self.diag.values.update({"source": spec.kind, "frames": 0, "reopens": 0, "fps": 0.0,
                                 "bad_frames": 0, "too_large": 0})
        self.warn = RateLimitedLog(node.log)
        self._frame_rate = RateCounter(window_s=2.0)

    def _size(self, frame: np.ndarray) -> np.ndarray:
        w, h = self.s.width, self.s.height
        fh, fw = frame.shape[:2]
        if self.spec.kind == "sim" or (w is None and h is None):
            return frame
        tw = w or max(1, round(fw * (h or fh) / fh))
        th = h or max(1, round(fh * tw / fw))
        if (tw, th) == (fw, fh):
            return frame
        return cv2.resize(frame, (tw, th), interpolation=cv2.INTER_AREA)

    def _message(self, frame: np.ndarray, stamp_ns: int) -> m.Image | None:
        h, w = frame.shape[:2]
        data = (jpeg.encode(frame, self.s.jpeg_quality) if self.s.encoding == "jpeg"
                else np.ascontiguousarray(frame).tobytes())
        if data is None:
            return None
        return m.Image(stamp_ns=stamp_ns, frame_id=self.frame_id, width=w, height=h,
                       encoding=self.s.encoding, data=data)

    def _checked(self, frame: np.ndarray, stamp_ns: int) -> m.Image | None:
        """The message for a frame as delivered, or None (counted, warned) when it
        cannot become a valid `Image`: the loop goes on with the next frame."""
        try:
            bgr = frames.to_bgr8(self._size(frames.to_bgr8(frame, max_side=None)))
        except frames.FrameRefused as refused:
            self.diag.increment(refused.reason)
            self.warn.warning(f"refused:{refused.reason}", "dropped a frame from %s: %s",
                              self.spec.kind, refused.text)
            return None
        except cv2.error as exc:  # resize of a degenerate frame
            self.diag.increment("bad_frames")
            self.warn.warning("cv-error", "dropped a frame from %s: %s", self.spec.kind,
                              clip(exc))
            return None
        msg = self._message(bgr, stamp_ns)
        if msg is None:
            self.diag.increment("bad_frames")
            self.warn.warning("encode", "dropped a %dx%d frame: JPEG encoding failed",
                              bgr.shape[1], bgr.shape[0])
        elif len(msg.data) + len(msg.frame_id) + MESSAGE_OVERHEAD > self.pub.topic.max_bytes:
            # Every subscriber would drop it unread (and the link refuse it).
            self.diag.increment("too_large")
            self.warn.warning("too-large", "dropped a %dx%d %s frame of %d bytes: above the "
                              "image message limit of %d bytes (use encoding jpeg or a "
                              "smaller width/height)", bgr.shape[1], bgr.shape[0],
                              msg.encoding, len(msg.data), self.pub.topic.max_bytes)
            return None
        return msg

    def _open(self) -> bool:
        """Open the source, retrying with backoff until it works or we are stopped."""
        stop = self.node.stop_event
        while not stop.is_set():
            if self.source.open():
                return True
            delay = self.backoff.next()
            self.diag.increment("open_failures")
            self.diag.set("ERROR", f"cannot open {self.spec.kind} {self.spec.target!r}; "
                          f"retrying in {delay:.1f} s")
            stop.wait(delay)
        return False

    def _period(self) -> float:
        if self.spec.kind == "sim":
            return 1.0 / (self.s.fps or DEFAULT_FPS)
        if self.spec.finite:
            return 1.0 / (self.s.fps or self.source.native_fps() or DEFAULT_FPS)
        return 1.0 / self.s.fps if self.s.fps else 0.0

    def run(self) -> int:
        """Capture until stopped, or until a file ends (exit status 0)."""
        stop = self.node.stop_event
        while not stop.is_set():
            if not self._open():
                break
            period = self._period()
            frames_this_open = 0
            next_t = time.monotonic()
            while not stop.is_set():
                frame = self.source.read()
                stamp_ns = m.now_ns()
                if frame is None:
                    break
                frames_this_open += 1
                if frames_this_open == 1:
                    self.backoff.reset()
                    self.diag.set("OK", f"capturing from {self.spec.kind} {self.spec.target!r}"
                                  if self.spec.target else f"capturing from {self.spec.kind}")
                msg = self._checked(frame, stamp_ns)
                if msg is not None:
                    self.pub.put(msg)
                    self.diag.increment("frames")
                    self._rate()
                if period > 0:
                    next_t += period
                    delay = next_t - time.monotonic()
                    if delay > 0:
                        stop.wait(delay)
                    else:
                        next_t = time.monotonic()  # fell behind: do not burst to catch up
            self.source.release()
            if stop.is_set():
                break
            if self.spec.finite and frames_this_open > 0:
                if not self.s.loop:
                    self.node.log.info("end of %s %r after %s frames", self.spec.kind,
                                       self.spec.target, self.diag.values.get("frames"))
                    self.diag.set("OK", "end of input")
                    return 0
                continue
            # A live camera stopped delivering (unplugged, stream dropped), or a
            # file yielded nothing: report and reopen with backoff.
            self.diag.increment("reopens")
            delay = self.backoff.next()
            self.diag.set("ERROR", f"{self.spec.kind} {self.spec.target!r} stopped delivering "
                          f"frames; reopening in {delay:.1f} s")
            stop.wait(delay)
        return 0

    def _rate(self) -> None:
        fps = self._frame_rate.add(time.monotonic())
        if fps is not None:
            self.diag.values["fps"] = round(fps, 1)


def sim_source(ctx: ServiceContext, settings: CameraSettings) -> SimSource:
    """The simulated world of `[sim]`, filmed through the lens the detector measures with."""
    world, clock, _ = world_from(ctx)
    width, height = settings.width or 640, settings.height or 480
    d = ctx.config.section(FaceDetectorSettings)
    try:
        k = Intrinsics.resolve(width, height, d.fx, d.fy, d.cx, d.cy, d.hfov_deg)
    except ValueError as exc:
        raise ConfigError(f"face_detector: {exc}") from None
    return SimSource(world, clock, Lens(k.fx, k.fy, k.cx, k.cy, width, height))


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    try:
        spec = parse_source(settings.source, settings.sim)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    if spec.kind in ("file", "sequence") and not spec.target.startswith("/"):
        spec = SourceSpec(spec.kind, str(resolve_path(
            ctx.config, spec.target,
            from_command_line=given(ctx.args, CameraSettings, "source"))))
    cv2.setNumThreads(1)
    source = sim_source(ctx, settings) if spec.kind == "sim" else \
        make_source(spec, settings.width, settings.height)
    node = ctx.node()
    LiveSettings(settings).serve(node)  # readable and dumpable; every field needs a restart
    try:
        return Capture(node, settings, spec, source).run()
    finally:
        node.close()
