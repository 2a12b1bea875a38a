"""Sound name resolution, the reply convention and the shipped sounds."""

from __future__ import annotations

from pathlib import Path

import miniaudio
import pytest

from buddybot.audio import access, protocol, sounds
from buddybot.audio.settings import AudioSettings
from buddybot.runtime.config import parse_config
from buddybot.runtime.errors import ConfigError


def test_shipped_sounds_exist_are_short_and_decode() -> None:
    for name, value in AudioSettings().sounds.items():
        path = sounds.resolve_file(value, None)
        assert path.is_file(), name
        assert path.stat().st_size < 200_000
        info = miniaudio.wav_get_file_info(str(path))
        assert 1.0 < info.duration < 4.0


def test_relative_paths_prefer_the_config_folder_then_the_package(tmp_path: Path) -> None:
    assert sounds.resolve_file("sounds/greeting.wav", tmp_path) == (
        sounds.PACKAGE_DIR / "sounds/greeting.wav")
    (tmp_path / "sounds").mkdir()
    mine = tmp_path / "sounds/greeting.wav"
    mine.write_bytes(b"x")
    assert sounds.resolve_file("sounds/greeting.wav", tmp_path) == mine
    assert sounds.resolve_file("/abs/x.wav", tmp_path) == Path("/abs/x.wav")
    assert sounds.resolve_file("nowhere.wav", tmp_path) == tmp_path / "nowhere.wav"


def test_say_prefix() -> None:
    assert sounds.parse_sound("say: Hello there ", None) == sounds.SpokenSound("Hello there")
    assert sounds.parse_sound("/tmp/a.ogg", None) == sounds.FileSound(Path("/tmp/a.ogg"))
    with pytest.raises(ValueError, match="empty text"):
        sounds.parse_sound("say:  ", None)
    with pytest.raises(ValueError, match="empty file"):
        sounds.parse_sound(" ", None)


def test_configured_sounds_extend_the_defaults() -> None:
    config = parse_config('[audio.sounds]\ngreeting = "mine.wav"\nhi = "say:Hi"\n')
    table = sounds.effective_sounds(config.audio.sounds, AudioSettings().sounds)
    assert table == {"greeting": "mine.wav", "farewell": "sounds/farewell.wav", "hi": "say:Hi"}


def test_bad_audio_config_is_an_error_naming_the_key() -> None:
    with pytest.raises(ConfigError, match=r"audio_player\.volume"):
        parse_config("[audio_player]\nvolume = 7.0\n")
    with pytest.raises(ConfigError, match="busy_policy"):
        parse_config('[audio]\nbusy_policy = "queue"\n')
    with pytest.raises(ConfigError, match="unknown key"):
        parse_config("[audio_player]\nloudness = 1\n")


def test_format_hint_names_the_problem() -> None:
    assert "unsupported format '.aiff'" in sounds.format_hint(Path("x.aiff"))
    assert "corrupt" in sounds.format_hint(Path("x.wav"))


def test_duration_round_trips_through_the_reply_message() -> None:
    text = protocol.playing_message("greeting", 2.7545)
    assert text == "playing greeting (2.755 s)"
    assert protocol.parse_duration(text) == pytest.approx(2.755)
    assert protocol.parse_duration("stopped") is None


def test_default_sound_dirs_are_the_package_and_the_configured_files_folders(
    tmp_path: Path
) -> None:
    (tmp_path / "mine").mkdir()
    table = {"beep": "mine/beep.wav", "hi": "say:Hi", "bad": " "}
    dirs = access.sound_dirs(None, table, tmp_path)
    assert dirs == ((sounds.PACKAGE_DIR / "sounds").resolve(), (tmp_path / "mine").resolve())
    assert access.sound_dirs(["a", "/abs/b"], table, tmp_path) == (
        (tmp_path / "a").resolve(), Path("/abs/b"))


def test_only_files_inside_the_sound_dirs_are_allowed(tmp_path: Path) -> None:
    box = tmp_path / "box"
    box.mkdir()
    (box / "in.wav").write_bytes(b"x")
    (tmp_path / "secret.wav").write_bytes(b"x")
    (box / "link.wav").symlink_to(tmp_path / "secret.wav")
    (box / "passwd.wav").symlink_to("/etc/passwd")
    dirs = (box.resolve(),)
    assert access.allowed_file(str(box / "in.wav"), dirs) == (box / "in.wav").resolve()
    assert access.allowed_file("in.wav", dirs) == (box / "in.wav").resolve()  # relative: in a dir
    assert access.allowed_file("gone.wav", dirs) == (box / "gone.wav").resolve()  # says missing
    for outside in ["/etc/passwd", "/no/such/file.wav", str(tmp_path / "secret.wav"),
                    str(box / ".." / "secret.wav"), "../secret.wav", str(box / "link.wav"),
                    "link.wav", str(box / "passwd.wav"), "bad\0name.wav", "/", ""]:
        assert access.allowed_file(outside, dirs) is None, outside
