"""Frame sources behind one small interface: OpenCV capture, or the simulation.

`--source` is parsed the way users write it: a number is a device index
(`0` = /dev/video0), something with `://` is a URL (RTSP, HTTP MJPEG),
something with a printf pattern (`frames/%04d.png`) is an image sequence,
anything else a video file. Files and sequences are *finite* (they end,
and are paced at an fps); devices, URLs and the simulation are *live*.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal, Protocol

import cv2
import numpy as np

from buddybot.camera.world_view import WorldCamera
from buddybot.sim.clock import SimClock
from buddybot.sim.views import Lens
from buddybot.sim.world import World

Kind = Literal["device", "url", "sequence", "file", "sim"]
_PATTERN = re.compile(r"%0?\d*d")


@dataclass(frozen=True)
class SourceSpec:
    kind: Kind
    target: str

    @property
    def finite(self) -> bool:
        return self.kind in ("sequence", "file")


def parse_source(text: str, sim: bool = False) -> SourceSpec:
    """What `--source TEXT` means (pure)."""
    if sim:
        return SourceSpec("sim", "")
    text = text.strip()
    if not text:
        raise ValueError("no camera source: give --source (device index, file, URL, "
                         "pattern) or --sim")
    if text.isdigit():
        return SourceSpec("device", text)
    if "://" in text:
        return SourceSpec("url", text)
    if _PATTERN.search(text):
        return SourceSpec("sequence", text)
    return SourceSpec("file", text)


class FrameSource(Protocol):
    """`read()` gives a frame as delivered (any channels, uint8 or uint16), None when
    the source failed or ended; the capture loop converts or refuses it (`frames.py`)."""

    def open(self) -> bool: ...
    def read(self) -> np.ndarray | None: ...
    def release(self) -> None: ...
    def native_fps(self) -> float | None: ...


class CvSource:
    """An OpenCV VideoCapture; `read()` None means failed / ended."""

    def __init__(self, spec: SourceSpec, width: int | None = None,
                 height: int | None = None) -> None:
        self.spec = spec
        self.width, self.height = width, height
        self._cap: cv2.VideoCapture | None = None

    def open(self) -> bool:
        self.release()
        if self.spec.kind == "device":
            cap = cv2.VideoCapture(int(self.spec.target))
            if self.width:
                cap.set(cv2.CAP_PROP_FRAME_WIDTH, self.width)
            if self.height:
                cap.set(cv2.CAP_PROP_FRAME_HEIGHT, self.height)
        elif self.spec.kind == "sequence":
            cap = cv2.VideoCapture(self.spec.target, cv2.CAP_IMAGES)
        else:
            cap = cv2.VideoCapture(self.spec.target)
        if not cap.isOpened():
            cap.release()
            return False
        self._cap = cap
        return True

    def read(self) -> np.ndarray | None:
        if self._cap is None:
            return None
        try:
            ok, frame = self._cap.read()
        except cv2.error:
            return None
        if not ok or frame is None or frame.size == 0:
            return None
        return frame

    def native_fps(self) -> float | None:
        if self._cap is None:
            return None
        fps = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        return fps if 1.0 <= fps <= 240.0 else None

    def release(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None


class SimSource:
    """The simulated world as a live source, filmed at the shared scenario clock."""

    def __init__(self, world: World, clock: SimClock, lens: Lens) -> None:
        self._cam = WorldCamera(lens)
        self._world = world
        self._clock = clock

    def open(self) -> bool:
        return True

    def read(self) -> np.ndarray | None:
        return self._cam.frame(self._world.at(self._clock.now()))

    def native_fps(self) -> float | None:
        return None

    def release(self) -> None:
        pass


def make_source(spec: SourceSpec, width: int | None, height: int | None) -> FrameSource:
    """A camera or file source (the simulation is made with `SimSource`, from the world)."""
    if spec.kind == "sim":
        raise ValueError("the simulated camera needs its world: use SimSource")
    return CvSource(spec, width, height)
