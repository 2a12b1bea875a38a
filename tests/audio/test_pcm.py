"""The playback cursor: exact frame counts, stop/pause/resume, generations, volume."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.audio.pcm import Cursor, Track, apply_volume


def track(frames: int, channels: int = 2) -> Track:
    samples = np.arange(frames * channels, dtype=np.int16).reshape(frames, channels)
    return Track("t", samples, 48000)


def frames_of(data: bytes, channels: int = 2) -> np.ndarray:
    return np.frombuffer(data, dtype=np.int16).reshape(-1, channels)


def test_idle_cursor_gives_exact_silence() -> None:
    chunk = Cursor(2).take(480)
    assert len(chunk.data) == 480 * 4 and not any(chunk.data)
    assert chunk.audio_frames == 0 and chunk.finished is None


def test_plays_whole_track_then_pads_and_reports_start_and_end() -> None:
    cursor = Cursor(2)
    t = track(1000)
    gen = cursor.load(t)
    out = [cursor.take(480) for _ in range(3)]
    assert out[0].started == gen and out[1].started is None
    assert [c.audio_frames for c in out] == [480, 480, 40]
    assert out[2].finished == gen and out[0].finished is None
    joined = np.concatenate([frames_of(c.data) for c in out])
    assert np.array_equal(joined[:1000], t.samples)
    assert not joined[1000:].any()
    assert not cursor.active and cursor.take(10).audio_frames == 0


def test_pause_outputs_silence_and_resume_continues_where_it_was() -> None:
    cursor = Cursor(2)
    t = track(300)
    cursor.load(t)
    first = cursor.take(100)
    assert cursor.pause() and cursor.paused
    held = cursor.take(100)
    assert held.audio_frames == 0 and not any(held.data)
    assert cursor.resume() and not cursor.paused
    rest = cursor.take(200)
    played = np.concatenate([frames_of(first.data), frames_of(rest.data)])
    assert np.array_equal(played, t.samples)
    assert rest.finished is not None


def test_stop_pause_resume_when_idle_say_so() -> None:
    cursor = Cursor(2)
    assert not cursor.stop() and not cursor.pause() and not cursor.resume()
    cursor.load(track(10))
    assert not cursor.resume()  # playing, not paused
    assert cursor.stop() and not cursor.active
    assert cursor.take(10).audio_frames == 0


def test_load_replaces_and_bumps_generation() -> None:
    cursor = Cursor(2)
    g1 = cursor.load(track(1000))
    cursor.take(100)
    g2 = cursor.load(track(50))
    assert g2 == g1 + 1 and cursor.progress() == 0.0
    chunk = cursor.take(100)
    assert chunk.started == g2 and chunk.finished == g2 and chunk.audio_frames == 50


def test_progress_and_channel_mismatch() -> None:
    cursor = Cursor(2)
    cursor.load(track(200))
    cursor.take(50)
    assert cursor.progress() == pytest.approx(0.25)
    with pytest.raises(ValueError, match="channels"):
        cursor.load(track(10, channels=1))


def test_zero_or_negative_request_is_empty() -> None:
    cursor = Cursor(2)
    cursor.load(track(10))
    assert cursor.take(0).data == b"" and cursor.take(-5).data == b""


def test_volume_scales_and_clips() -> None:
    samples = np.array([[1000, -1000], [30000, -30000]], dtype=np.int16)
    assert apply_volume(samples, 1.0) is samples
    half = apply_volume(samples, 0.5)
    assert half.tolist() == [[500, -500], [15000, -15000]]
    loud = apply_volume(samples, 2.0)
    assert loud.tolist() == [[2000, -2000], [32767, -32768]] and loud.dtype == np.int16
