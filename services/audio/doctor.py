"""The audio player's part of `buddybot doctor`: its backend opens a device.

The player (and miniaudio) is imported only when the device is opened, so a
missing miniaudio is one failed check, not a doctor that cannot start.
"""

from __future__ import annotations

from buddybot.audio.settings import AudioPlayerSettings
from buddybot.runtime.health import FAIL, OK, WARN, Check, DoctorHooks


def check_audio(settings: AudioPlayerSettings, sim: bool, in_use: bool = False) -> Check:
    """The audio player's backend opens a device ("null" is fine in sim)."""
    backend = str(settings.backend)
    if backend == "null":
        return Check("audio device", OK if sim else WARN,
                     "null backend: the robot plays silently")
    if in_use:
        return Check("audio device", OK, f"{backend}: held by the running audio-player")
    try:
        from buddybot.audio.player import open_device
        opened = open_device(settings)
    except Exception as exc:  # AudioError, miniaudio errors: the message says why
        return Check("audio device", OK if sim else FAIL, f"{backend}: {exc}")
    try:
        if opened.warning:
            return Check("audio device", OK if sim else WARN, opened.warning)
        return Check("audio device", OK, f"{backend}: opened ({opened.backend})")
    finally:
        opened.device.close()


def _devices(settings: AudioPlayerSettings, sim: bool, in_use: bool) -> list[Check]:
    return [check_audio(settings, sim, in_use)]


PLAYER = DoctorHooks(devices=_devices)
