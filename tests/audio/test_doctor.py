"""The audio player's doctor check: the null backend, and a device held by the player."""

from __future__ import annotations

from buddybot.audio.doctor import check_audio
from buddybot.audio.settings import AudioPlayerSettings
from buddybot.runtime.health import OK, WARN


def test_audio_null_is_fine_in_sim_only() -> None:
    null = AudioPlayerSettings(backend="null")
    assert check_audio(null, sim=True).level == OK
    assert check_audio(null, sim=False).level == WARN


def test_a_device_held_by_the_player_is_not_opened_again() -> None:
    check = check_audio(AudioPlayerSettings(backend="alsa"), sim=False, in_use=True)
    assert check.level == OK and "held by the running audio-player" in check.detail
