"""Config tables `[audio]` and `[audio_player]` (pure msgspec structs).

Every field has a default that works on a headless box, so an empty
config file runs the robot; an unknown key or a wrong type is reported
at start-up by `buddybot.runtime.config`.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec


def _default_sounds() -> dict[str, str]:
    return {"greeting": "sounds/greeting.wav", "farewell": "sounds/farewell.wav"}


BusyPolicy = Literal["preempt", "refuse"]
Backend = Literal["auto", "null", "alsa", "pulseaudio"]


class AudioSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[audio]`: the play_sound action server.

    `sounds` maps a sound name to a file (relative to the config file, else
    to the package's own `sounds/`), or to text to speak when the value
    starts with `say:` (needs espeak-ng on the player's host).
    `busy_policy`: what a goal does while another one plays. "preempt"
    (default) cancels the running goal and plays the new one at once, so a
    farewell never waits for (or is refused by) a greeting still playing;
    "refuse" answers accepted=false while busy.
    """

    sounds: dict[str, str] = msgspec.field(default_factory=_default_sounds)
    busy_policy: Annotated[BusyPolicy, msgspec.Meta(
        extra={"live": True},
        description="what a goal does while another one plays")] = "preempt"
    player: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64,
        description="node name of the audio player that plays the sounds")] = "audio-player"
    """Node name of the player whose liveliness says it is running."""
    player_timeout_s: Annotated[float, msgspec.Meta(
        gt=0, le=3600.0, extra={"live": True},
        description="seconds a call to the player may take")] = 3.0
    """How long a call to the player may take before the goal is aborted."""
    progress_period_s: Annotated[float, msgspec.Meta(
        gt=0, le=60.0, description="seconds between PLAYING status messages")] = 0.1
    """How often PLAYING status with progress is published."""


class AudioPlayerSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[audio_player]`: the player process (miniaudio).

    `backend` "auto" tries PulseAudio, ALSA and JACK and falls back to the
    null device (plays in real time, no sound) with a warning, so a
    headless CI box or `up --sim` still works; "null" forces it; "alsa" /
    "pulseaudio" insist on that backend (no device: every play request is
    refused with a message). `device` is a substring of a playback device
    name (None: the system default). `volume` is a linear gain 0..2 applied
    to the samples. The device runs at `sample_rate`/`channels`; files are
    converted by miniaudio's decoder. `period_ms` is the device callback
    period: it bounds the start latency and the audio still buffered after
    a stop (about `period_ms` x 3).
    """

    backend: Annotated[Backend, msgspec.Meta(
        description="audio backend (auto: hardware, falling back to the silent null "
        "device)")] = "auto"
    device: Annotated[str, msgspec.Meta(
        description="playback device name (a substring; unset: the system default)",
    )] | None = None
    volume: Annotated[float, msgspec.Meta(
        ge=0.0, le=2.0, extra={"live": True},
        description="linear gain applied to the samples (1: unchanged; live: from the "
        "next sound)")] = 1.0
    sample_rate: Annotated[int, msgspec.Meta(
        ge=8000, le=192000, description="device sample rate, Hz")] = 48000
    channels: Annotated[int, msgspec.Meta(
        ge=1, le=8, description="device channels")] = 2
    period_ms: Annotated[int, msgspec.Meta(
        ge=1, le=200, description="ms per device callback: bounds start latency and "
        "the audio buffered after a stop")] = 10
    max_duration_s: Annotated[float, msgspec.Meta(
        gt=0, le=3600.0, extra={"live": True},
        description="seconds: longer sounds are refused")] = 60.0
    """Longer files are refused, from their header before decoding, and a file
    whose header lies is cut off at this length while decoding (refused too):
    a decoded sound never takes more than this many seconds of memory."""
    max_file_bytes: Annotated[int, msgspec.Meta(
        gt=0, le=2**31, extra={"live": True},
        description="bytes: larger files are refused unopened")] = 50_000_000
    """Larger files are refused before they are opened (a robot sound is a
    few hundred kB; 60 s of 48 kHz stereo WAV is 11.5 MB)."""
    sound_dirs: list[str] | None = None
    """Folders `audio/play_file` may play files from (relative: to the config
    file's folder). None: the package's own `sounds/` and the folder of every
    configured sound file. Paths are compared after resolving symlinks and
    `..`; anything else is refused with one text, whatever the reason."""
    cache_size: Annotated[int, msgspec.Meta(
        ge=0, le=4096, extra={"live": True},
        description="decoded files kept in memory (0: none)")] = 16
    """Decoded files kept in memory (configured sounds are decoded at start)."""
