"""The playback cursor: which samples go to the device next (pure, thread-safe).

The device callback asks for N frames every period; `Cursor.take` answers
with exactly N frames (track audio, then silence), so stop, pause and
resume act on the very next period without touching the device. Nothing
here knows about miniaudio or Zenoh: it is unit-tested with plain arrays.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Track:
    """Decoded audio in the device's format: int16 frames x channels."""

    name: str
    samples: np.ndarray
    sample_rate: int

    @property
    def frames(self) -> int:
        return int(self.samples.shape[0])

    @property
    def channels(self) -> int:
        return int(self.samples.shape[1])

    @property
    def duration_s(self) -> float:
        return self.frames / self.sample_rate


def apply_volume(samples: np.ndarray, volume: float) -> np.ndarray:
    """Linear gain with clipping to int16 (1.0 returns the samples untouched)."""
    if volume == 1.0:
        return samples
    scaled = np.rint(samples.astype(np.float32) * volume)
    clipped: np.ndarray = np.clip(scaled, -32768, 32767).astype(np.int16)
    return clipped


@dataclass
class Chunk:
    """What one device period gets.

    `data`: exactly the frames asked for (audio then zeros); `audio_frames`:
    how many of them came from the track; `finished`: the generation whose
    last sample is in this chunk (None otherwise); `started`: the generation
    whose first sample is in it.
    """

    data: bytes
    audio_frames: int
    finished: int | None = None
    started: int | None = None


@dataclass
class _State:
    track: Track | None = None
    position: int = 0
    paused: bool = False
    generation: int = 0
    fresh: bool = False


class Cursor:
    """Current track, position and pause flag, shared by the control and audio threads."""

    def __init__(self, channels: int) -> None:
        self.channels = channels
        self._lock = threading.Lock()
        self._s = _State()

    # -- control side --

    def load(self, track: Track) -> int:
        """Play `track` from its start, replacing whatever played; returns its generation."""
        if track.channels != self.channels:
            raise ValueError(f"track has {track.channels} channels, device {self.channels}")
        with self._lock:
            self._s.generation += 1
            self._s.track, self._s.position, self._s.paused = track, 0, False
            self._s.fresh = True
            return self._s.generation

    def stop(self) -> bool:
        """Drop the current track; True when something was loaded."""
        with self._lock:
            active = self._s.track is not None
            self._s.track, self._s.position, self._s.paused = None, 0, False
            return active

    def pause(self) -> bool:
        """Hold the position (silence goes out); False when nothing is loaded."""
        with self._lock:
            if self._s.track is None:
                return False
            self._s.paused = True
            return True

    def resume(self) -> bool:
        """Continue a paused track; False when nothing is paused."""
        with self._lock:
            if self._s.track is None or not self._s.paused:
                return False
            self._s.paused = False
            return True

    @property
    def active(self) -> bool:
        with self._lock:
            return self._s.track is not None

    @property
    def paused(self) -> bool:
        with self._lock:
            return self._s.paused

    @property
    def generation(self) -> int:
        with self._lock:
            return self._s.generation

    def progress(self) -> float:
        """Fraction of the current track handed to the device (0 when idle)."""
        with self._lock:
            track = self._s.track
            return 0.0 if track is None or track.frames == 0 else self._s.position / track.frames

    # -- audio side --

    def take(self, frames: int) -> Chunk:
        """The next `frames` frames for the device, never more, never fewer."""
        frame_bytes = 2 * self.channels
        with self._lock:
            s = self._s
            if s.track is None or s.paused or frames <= 0:
                return Chunk(bytes(max(frames, 0) * frame_bytes), 0)
            start = s.position
            end = min(start + frames, s.track.frames)
            audio = s.track.samples[start:end].tobytes()
            s.position = end
            started = s.generation if s.fresh else None
            s.fresh = False
            finished = None
            if end >= s.track.frames:
                finished = s.generation
                s.track, s.position = None, 0
        count = end - start
        if count < frames:
            audio += bytes((frames - count) * frame_bytes)
        return Chunk(audio, count, finished, started)
