"""The playback engine: decode a file, stream it to a miniaudio device, control it.

The device runs all the time and pulls `period_ms` of samples per callback
from a `Cursor`: play, stop, pause and resume only change the cursor, so
they take effect on the next period (~10 ms) without reopening the device,
and the first sample of a new sound goes out within one period. Files are
decoded whole (robot sounds are short) into the device's format, and kept
in a small cache; the configured sounds are decoded at start.

A file is checked before it costs anything: only configured sounds and
files in the allowed folders are opened (`access.py`), its size and the
duration in its header are checked first, and decoding streams from disk
and stops at `max_duration_s` (a header that lies cannot make the player
allocate more than that).

No Zenoh here: `player_service.py` wires this to keys. A `tap` callback
receives every audio sample handed to the device (tests compare it with
the file).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import os
import queue
import stat
import threading
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import miniaudio
import numpy as np

from buddybot.audio import access, tts
from buddybot.audio import sounds as snd
from buddybot.audio.pcm import Chunk, Cursor, Track, apply_volume
from buddybot.audio.settings import AudioPlayerSettings
from buddybot.contract import messages as m
from buddybot.runtime import limits

log = logging.getLogger("buddybot.audio.player")

_HARDWARE_BACKENDS = (miniaudio.Backend.PULSEAUDIO, miniaudio.Backend.ALSA,
                      miniaudio.Backend.JACK)
_NAMED_BACKENDS = {"null": miniaudio.Backend.NULL, "alsa": miniaudio.Backend.ALSA,
                   "pulseaudio": miniaudio.Backend.PULSEAUDIO}


class AudioError(Exception):
    """A sound that cannot be played; the message names the file and the reason."""


def _why(exc: BaseException) -> str:
    """miniaudio errors carry (text, code) args: make them read as one phrase."""
    return ", code ".join(str(a) for a in exc.args) or type(exc).__name__


# --- decoding -----------------------------------------------------------------------


STREAM_FRAMES = 16384
"""Frames decoded per step (miniaudio's stream buffer): memory grows by this much
at a time, so the length cap is checked long before a huge file is decoded."""


def check_file(path: Path, *, max_file_bytes: int, max_duration_s: float) -> None:
    """Refuse a missing, special, empty, too large or (by its header) too long file
    before anything is read or decoded."""
    try:
        st = path.stat()
    except FileNotFoundError:
        raise AudioError(f"{path}: no such file") from None
    except OSError as exc:
        raise AudioError(f"{path}: cannot read: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise AudioError(f"{path}: not a regular file")
    if st.st_size == 0:
        raise AudioError(f"{path}: empty file")
    if st.st_size > max_file_bytes:
        raise AudioError(f"{path}: {st.st_size} bytes, more than max_file_bytes "
                         f"({max_file_bytes})")
    if not os.access(path, os.R_OK):
        raise AudioError(f"{path}: cannot read: permission denied")
    try:
        info = miniaudio.get_file_info(str(path))
    except miniaudio.MiniaudioError:
        return  # no readable header for its suffix: the decoder says why
    if info.sample_rate > 0 and info.num_frames / info.sample_rate > max_duration_s:
        raise AudioError(f"{path}: {info.num_frames / info.sample_rate:.0f} s long, more "
                         f"than max_duration_s ({max_duration_s:g} s)")


def _stream_decode(path: Path, sample_rate: int, channels: int, max_frames: int
                   ) -> np.ndarray:
    """Decode step by step into int16 samples, refusing past `max_frames` frames."""
    parts: list[np.ndarray] = []
    frames = 0
    stream = miniaudio.stream_file(str(path), miniaudio.SampleFormat.SIGNED16, channels,
                                   sample_rate, frames_to_read=STREAM_FRAMES)
    with contextlib.closing(stream):
        for chunk in stream:
            part = np.frombuffer(chunk, dtype=np.int16)
            frames += part.size // channels
            if frames > max_frames:
                raise AudioError(f"{path}: longer than max_duration_s "
                                 f"({max_frames / sample_rate:g} s)")
            parts.append(part)
    return np.concatenate(parts) if parts else np.zeros(0, np.int16)


def decode_file(path: Path, *, name: str, sample_rate: int, channels: int,
                volume: float = 1.0, max_duration_s: float = 60.0,
                max_file_bytes: int = 50_000_000) -> Track:
    """Decode any WAV/FLAC/MP3/Ogg Vorbis file into int16 frames at the device rate."""
    check_file(path, max_file_bytes=max_file_bytes, max_duration_s=max_duration_s)
    try:
        samples = _stream_decode(path, sample_rate, channels,
                                 int(max_duration_s * sample_rate))
    except miniaudio.MiniaudioError as exc:
        raise AudioError(f"{path}: {snd.format_hint(path)} (miniaudio: {_why(exc)})") from None
    usable = samples.size - samples.size % channels
    samples = samples[:usable].reshape(-1, channels)
    if samples.shape[0] == 0:
        raise AudioError(f"{path}: contains no audio")
    samples = np.ascontiguousarray(apply_volume(samples, volume))
    return Track(name=name, samples=samples, sample_rate=sample_rate)


# --- the device ---------------------------------------------------------------------


@dataclass
class OpenedDevice:
    device: miniaudio.PlaybackDevice
    backend: str
    warning: str | None = None


def _find_device(backends: list[miniaudio.Backend], name: str) -> Any:
    devices = miniaudio.Devices(backends=backends)
    playbacks = devices.get_playbacks()
    for info in playbacks:
        if name.lower() in str(info["name"]).lower():
            return info["id"]
    names = ", ".join(repr(i["name"]) for i in playbacks) or "none"
    raise AudioError(f"no playback device matching {name!r} (found: {names})")


def _open(backends: list[miniaudio.Backend], device: str | None, settings: AudioPlayerSettings
          ) -> miniaudio.PlaybackDevice:
    device_id = _find_device(backends, device) if device else None
    return miniaudio.PlaybackDevice(
        output_format=miniaudio.SampleFormat.SIGNED16, nchannels=settings.channels,
        sample_rate=settings.sample_rate, buffersize_msec=settings.period_ms,
        device_id=device_id, backends=backends, app_name="buddybot",
    )


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence the C libraries while probing: libasound prints ~30 lines of
    "cannot find card" on a box without sound, and the fallback warning
    already says what happened."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def open_device(settings: AudioPlayerSettings) -> OpenedDevice:
    """Open the configured backend; "auto" falls back to the null device with a warning."""
    if settings.backend == "auto":
        hardware = [b for b in _HARDWARE_BACKENDS if miniaudio.is_backend_enabled(b)]
        try:
            with _quiet_stderr():
                dev = _open(hardware, settings.device, settings)
            return OpenedDevice(dev, dev.backend)
        except (miniaudio.MiniaudioError, AudioError) as exc:
            reason = f"no audio hardware ({_why(exc)}); playing on the null device (silent)"
            dev = _open([miniaudio.Backend.NULL], None, settings)
            return OpenedDevice(dev, dev.backend, reason)
    backend = _NAMED_BACKENDS[settings.backend]
    device = None if settings.backend == "null" else settings.device
    try:
        dev = _open([backend], device, settings)
    except miniaudio.MiniaudioError as exc:
        raise AudioError(f"cannot open {settings.backend} audio device: {_why(exc)}") from None
    return OpenedDevice(dev, dev.backend)


# --- the player ---------------------------------------------------------------------


@dataclass
class PlayerStats:
    plays: int = 0
    finished: int = 0
    stops: int = 0
    failures: int = 0
    last_request_ns: int = 0
    last_first_sample_ns: int = 0
    last_decode_ms: float = 0.0
    last_stop_ns: int = 0


class Player:
    """Plays one sound at a time on an always-running device.

    `on_busy(bool)` is called (from a control or the watcher thread, never
    the audio thread) whenever the device becomes busy or free; `on_started`
    when the first sample of a sound was handed to the device.
    """

    def __init__(
        self,
        settings: AudioPlayerSettings,
        sounds: dict[str, str],
        config_dir: Path | None,
        *,
        on_busy: Callable[[bool], None] = lambda _b: None,
        on_started: Callable[[], None] = lambda: None,
        tap: Callable[[bytes], None] | None = None,
    ) -> None:
        self.settings = settings
        self.sounds = sounds
        self.config_dir = config_dir
        self.sound_dirs = access.sound_dirs(settings.sound_dirs, sounds, config_dir)
        """The folders play requests may name files in (resolved)."""
        self.cursor = Cursor(settings.channels)
        self.stats = PlayerStats()
        self._on_busy = on_busy
        self._on_started = on_started
        self._tap = tap
        self._render_lock = threading.Lock()
        self._control = threading.RLock()
        self._busy = False
        self._cache: collections.OrderedDict[tuple[str, int, int], Track] = (
            collections.OrderedDict()
        )
        self._events: queue.SimpleQueue[tuple[str, int, int]] = queue.SimpleQueue()
        self._closed = threading.Event()
        self._device: OpenedDevice | None = None
        self.device_error: str | None = None
        self._watcher = threading.Thread(target=self._watch, name="player-events", daemon=True)

    # -- lifetime --

    def open(self) -> OpenedDevice | None:
        """Open and start the device; None (and `device_error`) when there is none."""
        try:
            self._device = open_device(self.settings)
        except (AudioError, miniaudio.MiniaudioError) as exc:
            self.device_error = str(exc)
            return None
        feed = self._feed()
        next(feed)
        self._device.device.start(feed)
        self._watcher.start()
        return self._device

    def close(self) -> None:
        self._closed.set()
        self._events.put(("close", 0, 0))
        if self._device is not None:
            self._device.device.close()
            self._device = None

    @property
    def backend(self) -> str | None:
        return None if self._device is None else self._device.backend

    # -- control --

    def apply_settings(self, settings: AudioPlayerSettings) -> None:
        """A live parameter change (`buddybot param set audio-player volume 0.5`).
        Decoded tracks carry the old gain, so the cache is emptied: the next
        sound is decoded with the new settings; the one playing goes on as it
        is. Device settings (backend, rate, channels, period) are restart-only."""
        with self._control:
            self.settings = settings
            self._cache.clear()

    @property
    def busy(self) -> bool:
        return self._busy

    def resolve(self, name_or_path: str) -> tuple[str, Path]:
        """(display name, file) for a configured sound name or an allowed file, as
        it is or `file:<path>` (else `access.REFUSAL`, whatever the reason); may
        render speech."""
        if name_or_path not in self.sounds:
            try:
                spoken = m.spoken_text(name_or_path)
                file = m.sound_file(name_or_path) or name_or_path
            except ValueError as exc:
                raise AudioError(str(exc)) from None
            if spoken is not None:
                return self._speak(name_or_path, spoken)
            path = access.allowed_file(file, self.sound_dirs)
            if path is None:
                raise AudioError(access.REFUSAL)
            return name_or_path, path
        try:
            sound = snd.parse_sound(self.sounds[name_or_path], self.config_dir)
        except ValueError as exc:
            raise AudioError(f"sound {name_or_path!r}: {exc}") from None
        if isinstance(sound, snd.SpokenSound):
            return self._speak(name_or_path, sound.text)
        return name_or_path, sound.path

    @staticmethod
    def _speak(name: str, text: str) -> tuple[str, Path]:
        """(name, the WAV file speaking `text`), rendered by espeak-ng on first use."""
        try:
            return name, tts.render(text)
        except tts.TtsError as exc:
            raise AudioError(f"sound {limits.clip(name)!r}: {exc}") from None

    def load(self, name_or_path: str) -> Track:
        """The decoded track (cached by path, size and modification time)."""
        name, path = self.resolve(name_or_path)
        try:
            st = path.stat()
            key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
        except OSError:
            key = None
        if key is not None and key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        began = time.perf_counter()
        try:
            track = decode_file(path, name=name, sample_rate=self.settings.sample_rate,
                                channels=self.settings.channels, volume=self.settings.volume,
                                max_duration_s=self.settings.max_duration_s,
                                max_file_bytes=self.settings.max_file_bytes)
        except AudioError as exc:
            if name != str(path):
                raise AudioError(f"sound {name!r}: {exc}") from None
            raise
        self.stats.last_decode_ms = (time.perf_counter() - began) * 1e3
        if key is not None and self.settings.cache_size > 0:
            self._cache[key] = track
            while len(self._cache) > self.settings.cache_size:
                self._cache.popitem(last=False)
        return track

    def preload(self) -> list[str]:
        """Decode every configured sound now; returns the problems (not fatal)."""
        problems = []
        for name in self.sounds:
            try:
                self.load(name)
            except AudioError as exc:
                problems.append(str(exc))
        return problems

    def play(self, name_or_path: str) -> Track:
        """Start playing (replacing what plays); raises AudioError with the reason."""
        request_ns = time.time_ns()
        if self._device is None:
            self.stats.failures += 1
            raise AudioError(f"no audio device: {self.device_error}")
        try:
            track = self.load(name_or_path)
        except AudioError:
            self.stats.failures += 1
            raise
        with self._control:
            self.stats.plays += 1
            self.stats.last_request_ns = request_ns
            with self._render_lock:
                self.cursor.load(track)
            self._set_busy(True)
        return track

    def stop(self) -> bool:
        """Stop at once; True when something was playing."""
        with self._control:
            with self._render_lock:
                was = self.cursor.stop()
            if was:
                self.stats.stops += 1
                self.stats.last_stop_ns = time.time_ns()
            self._set_busy(False)
            return was

    def pause(self) -> bool:
        with self._control, self._render_lock:
            return self.cursor.pause()

    def resume(self) -> bool:
        with self._control, self._render_lock:
            return self.cursor.resume()

    def _set_busy(self, busy: bool) -> None:
        if busy != self._busy:
            self._busy = busy
            self._on_busy(busy)

    # -- audio thread --

    def _render(self, frames: int) -> bytes:
        with self._render_lock:
            chunk: Chunk = self.cursor.take(frames)
            if chunk.audio_frames and self._tap is not None:
                try:
                    self._tap(chunk.data[: chunk.audio_frames * 2 * self.settings.channels])
                except Exception as exc:  # a broken tap must not silence the robot
                    log.warning("audio tap failed, disabled: %r", exc)
                    self._tap = None
        if chunk.started is not None:
            self._events.put(("started", chunk.started, time.time_ns()))
        if chunk.finished is not None:
            self._events.put(("finished", chunk.finished, time.time_ns()))
        return chunk.data

    def _feed(self) -> Generator[bytes, int, None]:
        frames = yield b""
        while True:
            try:
                data = self._render(frames)
            except Exception as exc:  # never let the device lose its generator
                log.error("audio render failed: %r", exc)
                data = bytes(frames * 2 * self.settings.channels)
            frames = yield data

    # -- watcher thread: turns audio-thread events into busy/free changes --

    def _watch(self) -> None:
        while not self._closed.is_set():
            kind, generation, stamp = self._events.get()
            try:
                if kind == "started":
                    self.stats.last_first_sample_ns = stamp
                    self._on_started()
                elif kind == "finished":
                    with self._control:
                        if generation == self.cursor.generation and not self.cursor.active:
                            self.stats.finished += 1
                            self._set_busy(False)
            except Exception as exc:
                log.error("player event %s failed: %r", kind, exc)
