"""The audio services' part of `buddybot doctor`: the player's backend opens a
device; the `say:` sounds of `[audio]` have espeak-ng to speak them.

The player (and miniaudio) is imported only when the device is opened, so a
missing miniaudio is one failed check, not a doctor that cannot start.
"""

from __future__ import annotations

import shutil

from buddybot.audio.settings import AudioPlayerSettings, AudioSettings
from buddybot.audio.tts import ESPEAK
from buddybot.contract.messages import TTS_PREFIX
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


INSTALL_ESPEAK = "sudo apt-get install espeak-ng"


def check_speech(settings: AudioSettings, sim: bool) -> list[Check]:
    """With a `say:` sound configured, espeak-ng must be on PATH: without it
    that sound ends ABORTED on every play. No `say:` sound, no check (a goal
    may still ask for `say:<text>`; the player's refusal names espeak-ng)."""
    spoken = sorted(name for name, value in settings.sounds.items()
                    if value.startswith(TTS_PREFIX))
    if not spoken:
        return []
    names = ", ".join(spoken)
    found = shutil.which(ESPEAK)
    if found:
        return [Check("text-to-speech", OK, f"{ESPEAK}: {found} (say: sounds {names})")]
    return [Check("text-to-speech", WARN if sim else FAIL,
                  f"{ESPEAK} is not installed, so the say: sounds {names} cannot play "
                  f"(they end ABORTED); install it: {INSTALL_ESPEAK}")]


def _speech(settings: AudioSettings, sim: bool, _in_use: bool) -> list[Check]:
    return check_speech(settings, sim)


ACTION = DoctorHooks(devices=_speech)
"""The audio action's part: its `say:` sounds (espeak-ng renders them on the
player's host; doctor checks the host it runs on)."""
