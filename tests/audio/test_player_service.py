"""`buddybot run audio-player` as a real process behind a real router: direct play, stop,
pause and resume, and `buddybot param set audio-player volume 0.5` halving the next sound
with no restart. The tap file holds every sample handed to the null device."""

from __future__ import annotations

import subprocess
import time

import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.tools.testing import Collector, buddybot_argv, retry_until

from .conftest import RATE, beep_config, final, send_goal, tone, write_wav

pytestmark = pytest.mark.integration


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_volume_applies_to_the_next_sound(audio, probe, tmp_path, endpoint) -> None:
    config, samples = beep_config(tmp_path, 0.3)
    a = audio(config)
    assert a.player is not None
    pid = a.player.pid
    first = send_goal(probe, "beep")
    assert final(a, first.goal_id).state == "SUCCEEDED"

    result = param(endpoint, "set", "audio-player", "volume", "0.5")
    assert result.returncode == 0, result.stderr
    refused = param(endpoint, "set", "audio-player", "sample_rate", "44100")
    assert refused.returncode == 1 and "sample_rate needs a restart" in refused.stderr
    second = send_goal(probe, "beep")
    assert final(a, second.goal_id).state == "SUCCEEDED"
    assert a.player.pid == pid and a.player.alive()

    a.player.stop()  # the tap file is complete once the player exited
    tap = a.tap_samples().astype(np.int32)
    n = samples.shape[0]
    assert tap.shape[0] == 2 * n
    assert np.array_equal(tap[:n], samples)
    # Half the gain (rounded to int16), not the same sound again.
    assert np.abs(tap[n:] - samples.astype(np.int32) * 0.5).max() <= 1
    assert np.abs(tap[n:]).max() < np.abs(samples).max() * 0.6


def test_player_stop_pause_resume(audio, probe, tmp_path) -> None:
    samples = tone(1.0)
    path = write_wav(tmp_path / "direct.wav", samples)
    a = audio('[audio.sounds]\ndirect = "direct.wav"\n', action=False)  # allows tmp_path
    ok = retry_until(lambda: probe.call(keys.PLAY_FILE, m.PlayAudioFile(path=str(path))),
                     what="play_file answered")
    assert ok.success and "(1.000 s)" in ok.message, ok
    retry_until(lambda: len(a.tap_samples()) > RATE // 10, what="some audio")
    paused = probe.call(keys.AUDIO_PAUSE, m.Trigger())
    assert paused.success
    held = len(a.tap_samples())
    time.sleep(0.4)  # the scenario: stay paused a while (not a synchronisation)
    assert len(a.tap_samples()) == held
    assert [b.data for b in a.free.messages][-1] is False  # paused is still busy
    assert probe.call(keys.AUDIO_RESUME, m.Trigger()).success
    a.free.wait_for(lambda b: b.data and b.stamp_ns > 0 and len(a.free.messages) >= 3,
                    what="free after the end")
    assert [b.data for b in a.free.messages] == [True, False, True]
    assert not probe.call(keys.AUDIO_RESUME, m.Trigger()).success  # nothing paused
    assert not probe.call(keys.AUDIO_PAUSE, m.Trigger()).success  # nothing playing
    # stop while playing: free at once, the rest never handed over
    assert probe.call(keys.PLAY_FILE, m.PlayAudioFile(path=str(path))).success
    retry_until(lambda: len(a.tap_samples()) > samples.shape[0] + RATE // 20, what="audio")
    stopped = probe.call(keys.AUDIO_STOP, m.Trigger())
    assert stopped.success and stopped.message == "stopped"
    at_stop = len(a.tap_samples())
    a.free.wait_for(lambda b: len(a.free.messages) >= 5 and b.data, what="free after stop")
    assert probe.call(keys.AUDIO_STOP, m.Trigger()).message == "nothing was playing"
    a.player.stop()
    produced = a.tap_samples()
    assert len(produced) == at_stop < 2 * samples.shape[0]
    assert np.array_equal(produced[: samples.shape[0]], samples)  # first play, whole
    assert np.array_equal(produced[samples.shape[0]:], samples[: at_stop - samples.shape[0]])


def test_a_sound_asked_for_while_the_player_starts_is_not_ended_by_its_first_free(
        spawn, probe, tmp_path) -> None:
    """The player's first `device_free` (true) goes out before it answers any play
    request: sent after one, it says "free" while that sound plays, and the action
    server ends the sound's goal as stopped outside the action. Asked for every
    millisecond while the player starts, the first answered play lands as early as
    it can."""
    path = write_wav(tmp_path / "long.wav", tone(2.0))
    config = tmp_path / "buddybot.toml"
    config.write_text('[audio.sounds]\nlong = "long.wav"\n')  # allows tmp_path
    free = Collector(probe, keys.DEVICE_FREE)
    spawn("audio-player", "--config", str(config), "--backend", "null")
    asked: list[int] = []

    def play() -> m.TriggerReply:
        asked.append(time.time_ns())
        reply: m.TriggerReply = probe.call(keys.PLAY_FILE, m.PlayAudioFile(path=str(path)),
                                           timeout=3)
        return reply

    assert retry_until(play, 60, 0.001, "a play request answered").success
    end = free.wait_for(lambda b: b.data and b.stamp_ns > asked[-1], 30,
                        "free after the sound")
    assert (end.stamp_ns - asked[-1]) / 1e9 > 1.5, [
        (round((b.stamp_ns - asked[-1]) / 1e9, 3), b.data) for b in free.messages]
