"""The playback engine on the real miniaudio null device (plays in real time, no hardware)."""

from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from buddybot.audio import access
from buddybot.audio.player import AudioError, Player, decode_file
from buddybot.audio.settings import AudioPlayerSettings
from buddybot.tools.testing import retry_until

from .conftest import (
    CHANNELS,
    RATE,
    convert_with_sox,
    tone,
    write_silent_mp3,
    write_sparse_wav,
    write_wav,
)


class Recorder:
    """Collects what the player taps and the busy/free changes it reports."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.busy: list[bool] = []
        self.lock = threading.Lock()

    def tap(self, data: bytes) -> None:
        with self.lock:
            self.chunks.append(bytes(data))

    def on_busy(self, busy: bool) -> None:
        self.busy.append(busy)

    def samples(self) -> np.ndarray:
        with self.lock:
            raw = b"".join(self.chunks)
        return np.frombuffer(raw, dtype="<i2").reshape(-1, CHANNELS)


@pytest.fixture
def player_factory(tmp_path: Path) -> Iterator[Callable[..., tuple[Player, Recorder]]]:
    """Players on the null device that may play the test's own files (tmp_path)."""
    made: list[Player] = []

    def make(sounds: dict[str, str] | None = None, config_dir: Path | None = None,
             **settings: object) -> tuple[Player, Recorder]:
        rec = Recorder()
        conf = AudioPlayerSettings(**{  # type: ignore[arg-type]
            "backend": "null", "sound_dirs": [str(tmp_path)], **settings})
        player = Player(conf, sounds or {}, config_dir, on_busy=rec.on_busy, tap=rec.tap)
        made.append(player)
        assert player.open() is not None, player.device_error
        return player, rec

    yield make
    for player in made:
        player.close()


def test_plays_a_wav_in_real_time_and_the_tap_matches_the_file(player_factory, make_wav) -> None:
    path, samples = make_wav(seconds=0.4)
    player, rec = player_factory()
    began = time.monotonic()
    track = player.play(str(path))
    assert track.frames == samples.shape[0] and player.busy and rec.busy == [True]
    retry_until(lambda: not player.busy, timeout=10, what="playback end")
    assert time.monotonic() - began >= 0.4 * 0.9  # the null device keeps real time
    assert rec.busy == [True, False]
    assert np.array_equal(rec.samples(), samples)
    assert player.stats.finished == 1 and player.stats.last_first_sample_ns > 0


def test_stop_ends_at_once_and_nothing_is_handed_over_afterwards(player_factory, make_wav):
    path, samples = make_wav(seconds=3.0)
    player, rec = player_factory()
    player.play(str(path))
    retry_until(lambda: len(rec.samples()) > RATE // 10, what="some audio played")
    assert player.stop()
    after_stop = len(rec.samples())
    assert not player.busy and rec.busy == [True, False]
    assert after_stop < samples.shape[0]
    assert np.array_equal(rec.samples(), samples[:after_stop])
    # a later event (the next sound's end) proves no stray samples followed the stop
    short, short_samples = make_wav("short.wav", seconds=0.1)
    player.play(str(short))
    retry_until(lambda: not player.busy, what="second sound end")
    assert np.array_equal(rec.samples()[after_stop:], short_samples)
    assert not player.stop()  # idle: nothing to stop


def test_pause_holds_the_position_and_resume_continues(player_factory, make_wav) -> None:
    path, samples = make_wav(seconds=0.6)
    player, rec = player_factory()
    assert not player.pause() and not player.resume()
    player.play(str(path))
    retry_until(lambda: len(rec.samples()) > RATE // 10, what="some audio played")
    assert player.pause()
    held = len(rec.samples())
    time.sleep(0.3)  # the scenario: stay paused for a while (not a synchronisation)
    assert len(rec.samples()) == held and player.busy
    assert player.resume()
    retry_until(lambda: not player.busy, what="playback end")
    assert np.array_equal(rec.samples(), samples)


def test_new_sound_replaces_the_playing_one(player_factory, make_wav) -> None:
    long_path, _ = make_wav("long.wav", seconds=3.0)
    short_path, short = make_wav("short.wav", seconds=0.2, freq=660.0)
    player, rec = player_factory()
    player.play(str(long_path))
    retry_until(lambda: len(rec.samples()) > 0, what="first sound started")
    player.play(str(short_path))
    retry_until(lambda: not player.busy, what="replacement end")
    assert rec.busy == [True, False]  # busy throughout, free once
    assert np.array_equal(rec.samples()[-short.shape[0]:], short)


@pytest.mark.integration  # runs sox (a process) to make the FLAC and Ogg files
@pytest.mark.parametrize("suffix", [".flac", ".ogg"])
def test_flac_and_ogg_decode_to_the_right_length(tmp_path: Path, suffix: str) -> None:
    src = write_wav(tmp_path / "src.wav", tone(0.5))
    encoded = convert_with_sox(src, tmp_path / f"src{suffix}")
    track = decode_file(encoded, name="x", sample_rate=RATE, channels=CHANNELS)
    assert abs(track.frames - RATE // 2) < RATE // 50
    if suffix == ".flac":  # lossless
        assert np.array_equal(track.samples, tone(0.5))


def test_mp3_decodes(tmp_path: Path) -> None:
    path = write_silent_mp3(tmp_path / "quiet.mp3", frames=40)
    track = decode_file(path, name="x", sample_rate=44100, channels=1)
    assert track.frames == 40 * 1152 and not track.samples.any()


def test_resampling_and_channel_conversion(tmp_path: Path) -> None:
    path = write_wav(tmp_path / "mono.wav", tone(1.0, rate=22050, channels=1), rate=22050)
    track = decode_file(path, name="m", sample_rate=RATE, channels=CHANNELS)
    assert track.channels == 2 and abs(track.duration_s - 1.0) < 0.01


@pytest.mark.parametrize(("name", "content", "reason"), [
    ("missing.wav", None, "no such file"),
    ("empty.wav", b"", "empty file"),
    ("corrupt.wav", b"RIFF\x10\x00\x00\x00WAVEfmt garbage" * 20, "corrupt"),
    ("noise.mp3", bytes(range(256)) * 8, "not a valid"),
    ("text.aiff", b"hello, I am not audio" * 10, "unsupported format '.aiff'"),
])
def test_bad_files_are_refused_naming_file_and_reason(
    tmp_path: Path, name: str, content: bytes | None, reason: str
) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(AudioError) as err:
        decode_file(path, name=name, sample_rate=RATE, channels=CHANNELS)
    assert str(path) in str(err.value) and reason in str(err.value)


def test_directory_and_too_long_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(AudioError, match="not a regular file"):
        decode_file(tmp_path, name="d", sample_rate=RATE, channels=CHANNELS)
    path = write_wav(tmp_path / "long.wav", tone(1.0))
    with pytest.raises(AudioError, match="max_duration_s"):
        decode_file(path, name="l", sample_rate=RATE, channels=CHANNELS, max_duration_s=0.5)


def test_configured_names_resolve_and_failures_name_the_sound(player_factory, tmp_path):
    write_wav(tmp_path / "beep.wav", tone(0.1))
    player, _ = player_factory({"beep": "beep.wav", "gone": "gone.wav"}, tmp_path)
    assert player.play("beep").name == "beep"
    with pytest.raises(AudioError) as err:
        player.play("gone")
    assert "sound 'gone'" in str(err.value) and str(tmp_path / "gone.wav") in str(err.value)
    assert player.stats.failures == 1
    assert player.preload() == [str(err.value)]


def test_volume_is_applied(player_factory, make_wav) -> None:
    path, samples = make_wav(seconds=0.1)
    player, rec = player_factory(volume=0.5)
    player.play(str(path))
    retry_until(lambda: not player.busy, what="playback end")
    expected = np.rint(samples.astype(np.float32) * 0.5).astype(np.int16)
    assert np.array_equal(rec.samples(), expected)


@pytest.mark.skipif(shutil.which("espeak-ng") is None,
                    reason="espeak-ng not installed (scripts/test-packages.sh installs it)")
def test_text_to_speech_sound(player_factory) -> None:
    player, rec = player_factory({"hello": "say:Hello"})
    track = player.play("hello")
    assert 0.2 < track.duration_s < 3.0
    retry_until(lambda: not player.busy, what="speech end")
    assert np.abs(rec.samples()).max() > 1000  # audible speech, not silence


@pytest.mark.skipif(shutil.which("espeak-ng") is None,
                    reason="espeak-ng not installed (scripts/test-packages.sh installs it)")
def test_any_text_after_say_is_spoken_and_a_bad_text_refused(player_factory) -> None:
    player, rec = player_factory({})
    track = player.play("say:Any text at all")
    assert track.name == "say:Any text at all" and 0.3 < track.duration_s < 5.0
    retry_until(lambda: not player.busy, what="speech end")
    assert np.abs(rec.samples()).max() > 1000
    with pytest.raises(AudioError, match="non-printable"):
        player.play("say:two\nlines")


def test_missing_hardware_backend_is_reported_not_fatal() -> None:
    """`alsa` on a box without a sound card: no device, every play refused with why.
    (On a machine with a card the device opens and plays: checked too.)"""
    player = Player(AudioPlayerSettings(backend="alsa"), {}, None)
    try:
        opened = player.open()
        if opened is None:
            assert player.device_error and "alsa" in player.device_error
            with pytest.raises(AudioError, match="no audio device"):
                player.play("anything.wav")
        else:
            assert opened.backend.lower() == "alsa"
    finally:
        player.close()


def test_auto_backend_always_opens_something() -> None:
    player = Player(AudioPlayerSettings(backend="auto"), {}, None)
    try:
        opened = player.open()
        assert opened is not None
        assert opened.backend != "Null" or "null device" in (opened.warning or "")
    finally:
        player.close()


def test_files_outside_the_sound_dirs_get_one_refusal(player_factory, tmp_path) -> None:
    player, _ = player_factory()
    outside = tmp_path.parent / f"{tmp_path.name}-outside.wav"
    write_wav(outside, tone(0.1))
    try:
        answers = set()
        for request in ["/etc/passwd", "/no/such.wav", str(outside), f"../{outside.name}",
                        str(tmp_path / ".." / outside.name)]:
            with pytest.raises(AudioError) as err:
                player.play(request)
            answers.add(str(err.value))
        assert answers == {access.REFUSAL}
    finally:
        outside.unlink()


def test_a_file_request_is_a_file_of_the_sound_dirs_never_a_name(player_factory, tmp_path):
    write_wav(tmp_path / "chime.wav", tone(0.1))
    player, _ = player_factory(sounds={"greeting": "chime.wav"})
    assert player.resolve("file:chime.wav") == ("file:chime.wav", tmp_path / "chime.wav")
    assert player.resolve(f"file:{tmp_path / 'chime.wav'}")[1] == tmp_path / "chime.wav"
    (tmp_path.parent / f"{tmp_path.name}-dir").mkdir()
    (tmp_path / "out.wav").symlink_to("/etc/passwd")
    for request in ("file:../../etc/passwd", "file:/etc/passwd", "file:out.wav",
                    f"file:../{tmp_path.name}-dir", "file:/no/such.wav"):
        with pytest.raises(AudioError) as err:
            player.play(request)
        assert str(err.value) == access.REFUSAL, request
    # inside the sound dirs the player says what is wrong with the file; a name after
    # file: is a file name, never the configured sound nor a text to speak
    (tmp_path / "sub").mkdir()
    for request, why in (("file:sub", "not a regular file"), ("file:missing.wav", "no such"),
                         ("file:greeting", "no such"), ("file:say:hello", "no such")):
        with pytest.raises(AudioError, match=f"sound 'file:{request[5:]}': .*{why}"):
            player.play(request)


def test_long_and_large_files_are_refused_from_header_and_size(tmp_path: Path) -> None:
    long = write_sparse_wav(tmp_path / "long.wav", 30 * 60)
    with pytest.raises(AudioError, match=r"1800 s long, more than max_duration_s \(60 s\)"):
        decode_file(long, name="l", sample_rate=RATE, channels=CHANNELS)
    huge = tmp_path / "huge.wav"
    with huge.open("wb") as out:
        out.truncate(2 * 1024**3)  # sparse 2 GB
    with pytest.raises(AudioError, match="more than max_file_bytes"):
        decode_file(huge, name="h", sample_rate=RATE, channels=CHANNELS)


def test_decoding_stops_at_max_duration_when_no_header_says_the_length(tmp_path) -> None:
    """A suffix miniaudio has no header reader for: the streamed decode is cut off."""
    path = write_wav(tmp_path / "tone.snd", tone(1.0))
    with pytest.raises(AudioError, match="longer than max_duration_s"):
        decode_file(path, name="s", sample_rate=RATE, channels=CHANNELS, max_duration_s=0.5)
    assert decode_file(path, name="s", sample_rate=RATE, channels=CHANNELS).frames == RATE
