"""Audio test helpers: sound files with known samples, made by the tests themselves,
and both audio services started as processes on the test router."""

from __future__ import annotations

import shutil
import subprocess
import wave
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, retry_until

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
        pytest.skip("sox is not installed (needed to make FLAC/Ogg test files; "
                    "scripts/test-packages.sh installs it)")
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


@dataclass
class Audio:
    player: Process | None
    action: Process | None
    tap: Path
    free: Collector
    status: Collector

    def tap_samples(self) -> np.ndarray:
        return read_raw(self.tap) if self.tap.exists() else np.zeros((0, 2), np.int16)

    def alive(self) -> bool:
        return all(p.alive() for p in (self.player, self.action) if p is not None)


@pytest.fixture
def audio(spawn: Callable[..., Process], probe: Node, tmp_path: Path) -> Callable[..., Audio]:
    def start(config: str = "", *, player: bool = True, action: bool = True,
              action_args: tuple[str, ...] = ()) -> Audio:
        cfg = tmp_path / "buddybot.toml"
        cfg.write_text(config)
        tap = tmp_path / "tap.raw"
        free = Collector(probe, keys.DEVICE_FREE)
        status = Collector(probe, keys.PLAY_SOUND_STATUS)
        p = spawn("audio-player", "--config", str(cfg), "--backend", "null",
                  "--tap", str(tap)) if player else None
        a = spawn("audio", "--config", str(cfg), *action_args) if action else None
        if player:
            free.wait_for(lambda b: b.data, timeout=30, what="player up (device_free true)")
            # Its queryables come right after that sample; its parameters' last.
            retry_until(lambda: probe.call(keys.PARAMS, m.ParamRequest(op="list"), timeout=3,
                                           node="audio-player"), 30, 0.05,
                        "the player's queryables")
        return Audio(p, a, tap, free, status)

    return start


def send_goal(probe: Node, sound: str, timeout: float = 30.0) -> m.PlaySoundReply:
    """Send a goal, retrying only while the action server or the player is starting."""
    def attempt() -> m.PlaySoundReply | None:
        reply = probe.call(keys.PLAY_SOUND, m.PlaySound(sound=sound), timeout=3)
        return None if "not running" in reply.message else reply

    return retry_until(attempt, timeout, interval=0.1, what=f"goal {sound!r} answered")


def final(audio: Audio, goal_id: str, timeout: float = 30.0) -> m.PlaySoundStatus:
    return audio.status.wait_for(
        lambda s: s.goal_id == goal_id and s.state in m.TERMINAL_GOAL_STATES,
        timeout=timeout, what=f"end of goal {goal_id}")


def beep_config(tmp_path: Path, seconds: float, name: str = "beep", **extra: str) -> tuple[
        str, np.ndarray]:
    samples = tone(seconds)
    write_wav(tmp_path / f"{name}.wav", samples)
    lines = [f'{name} = "{name}.wav"'] + [f'{k} = "{v}"' for k, v in extra.items()]
    return "[audio.sounds]\n" + "\n".join(lines) + "\n", samples


def write_sparse_wav(path: Path, seconds: float, rate: int = 8000, channels: int = 1,
                     bits: int = 8) -> Path:
    """A valid PCM WAV header announcing `seconds` of audio, with the data left as a
    sparse hole: a long file that costs no disk space and no time to make."""
    frame_bytes = channels * bits // 8
    data = int(seconds * rate) * frame_bytes
    fmt = (b"fmt " + (16).to_bytes(4, "little") + (1).to_bytes(2, "little")
           + channels.to_bytes(2, "little") + rate.to_bytes(4, "little")
           + (rate * frame_bytes).to_bytes(4, "little") + frame_bytes.to_bytes(2, "little")
           + bits.to_bytes(2, "little"))
    header = (b"RIFF" + (36 + data).to_bytes(4, "little") + b"WAVE" + fmt
              + b"data" + data.to_bytes(4, "little"))
    with path.open("wb") as out:
        out.write(header)
        out.truncate(len(header) + data)
    return path
