"""Audio test helpers: sound files with known samples, made by the tests themselves."""

from __future__ import annotations

import shutil
import subprocess
import wave
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

RATE = 48000
CHANNELS = 2


def tone(seconds: float, freq: float = 440.0, rate: int = RATE, channels: int = CHANNELS,
         amplitude: int = 12000) -> np.ndarray:
    """A sine (left) and a different sine (right): int16 frames x channels, every sample
    distinct enough that a lost or repeated period shows up in a comparison."""
    t = np.arange(int(seconds * rate)) / rate
    cols = [np.sin(2 * np.pi * (freq * (1 + 0.5 * c)) * t) for c in range(channels)]
    ramp = np.linspace(0.2, 1.0, t.size)
    return (np.stack(cols, axis=1) * ramp[:, None] * amplitude).astype(np.int16)


def write_wav(path: Path, samples: np.ndarray, rate: int = RATE) -> Path:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(samples.shape[1])
        out.setsampwidth(2)
        out.setframerate(rate)
        out.writeframes(samples.astype("<i2").tobytes())
    return path


def write_silent_mp3(path: Path, frames: int = 40) -> Path:
    """An MPEG-1 Layer III file of `frames` silent frames (1152 samples each, 44.1 kHz
    mono, 128 kbit/s): a header, zero side information and zero main data, so no
    encoder is needed to make a valid MP3."""
    header = bytes([0xFF, 0xFB, 0x90, 0xC0])
    frame = header + bytes(417 - len(header))
    path.write_bytes(frame * frames)
    return path


def convert_with_sox(src: Path, dst: Path) -> Path:
    """FLAC / Ogg Vorbis copies of a WAV (sox is a test-only tool)."""
    if shutil.which("sox") is None:
        pytest.skip("sox is not installed (needed to make FLAC/Ogg test files)")
    subprocess.run(["sox", str(src), str(dst)], check=True, capture_output=True)
    return dst


def read_raw(path: Path, channels: int = CHANNELS) -> np.ndarray:
    data = np.frombuffer(path.read_bytes(), dtype="<i2")
    return data[: data.size - data.size % channels].reshape(-1, channels)


@pytest.fixture
def make_wav(tmp_path: Path) -> Callable[..., tuple[Path, np.ndarray]]:
    def make(name: str = "tone.wav", seconds: float = 0.5, **kw: float) -> tuple[Path, np.ndarray]:
        samples = tone(seconds, **kw)  # type: ignore[arg-type]
        return write_wav(tmp_path / name, samples), samples

    return make
