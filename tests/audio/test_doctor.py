"""The audio doctor checks: the null backend, a device held by the player, and
espeak-ng when a `say:` sound is configured (with and without it on PATH)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from buddybot.audio.doctor import INSTALL_ESPEAK, check_audio, check_speech
from buddybot.audio.settings import AudioPlayerSettings, AudioSettings
from buddybot.runtime.health import FAIL, OK, WARN
from buddybot.tools.testing import Process, buddybot_argv, free_port


def test_audio_null_is_fine_in_sim_only() -> None:
    null = AudioPlayerSettings(backend="null")
    assert check_audio(null, sim=True).level == OK
    assert check_audio(null, sim=False).level == WARN


def test_a_device_held_by_the_player_is_not_opened_again() -> None:
    check = check_audio(AudioPlayerSettings(backend="alsa"), sim=False, in_use=True)
    assert check.level == OK and "held by the running audio-player" in check.detail


SAY = AudioSettings(sounds={"greeting": "say:Hello there", "farewell": "sounds/farewell.wav"})


def test_no_say_sound_no_speech_check() -> None:
    assert check_speech(AudioSettings(), sim=False) == []


def test_a_say_sound_without_espeak_is_a_clear_finding(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))  # a PATH without espeak-ng
    [check] = check_speech(SAY, sim=False)
    assert check.level == FAIL and check.name == "text-to-speech"
    assert "espeak-ng is not installed" in check.detail and "greeting" in check.detail
    assert INSTALL_ESPEAK in check.detail and "farewell" not in check.detail
    assert check_speech(SAY, sim=True)[0].level == WARN


@pytest.mark.skipif(shutil.which("espeak-ng") is None,
                    reason="espeak-ng not installed (scripts/test-packages.sh installs it)")
def test_a_say_sound_with_espeak_is_ok() -> None:
    [check] = check_speech(SAY, sim=False)
    assert check.level == OK and shutil.which("espeak-ng") in check.detail  # type: ignore[operator]


@pytest.mark.integration
def test_doctor_names_the_missing_espeak(tmp_path: Path) -> None:
    """`buddybot doctor --quick` as a user runs it, on a host whose PATH has no
    espeak-ng and a config whose greeting is spoken: exit 1, one clear line."""
    config = tmp_path / "robot.toml"
    config.write_text('[audio.sounds]\ngreeting = "say:Hello there"\n')
    empty = tmp_path / "bin"
    empty.mkdir()
    proc = Process(buddybot_argv("doctor", "--quick", "--config", str(config), "--connect",
                                 f"tcp/127.0.0.1:{free_port()}"),
                   "doctor", tmp_path, env={"PATH": str(empty)})
    try:
        status = proc.proc.wait(60)
    finally:
        proc.stop()
    out = proc.output()
    [line] = [x for x in out.splitlines() if x[6:].startswith("text-to-speech ")]
    assert line.startswith("FAIL") and "espeak-ng is not installed" in line, out
    assert INSTALL_ESPEAK in line and status == 1, out
