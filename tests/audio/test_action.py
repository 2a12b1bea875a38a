"""`buddybot run audio` (the `audio/play_sound` action server) with its player: both
services as real processes, a real router, the real miniaudio null device.

The player writes every sample it hands to the device to a tap file, so a
test can check the produced audio against the file it asked for.
"""

from __future__ import annotations

import shutil
import threading
import time

import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import ServiceError
from buddybot.tools.testing import retry_until

from .conftest import beep_config, final, send_goal, tone, write_wav

pytestmark = pytest.mark.integration


def test_goal_succeeds_after_the_sounds_length_and_the_samples_match(
    audio, probe, tmp_path
) -> None:
    config, samples = beep_config(tmp_path, 0.8)
    a = audio(config)
    began = time.monotonic()
    reply = send_goal(probe, "beep")
    assert reply.accepted and reply.goal_id, reply
    end = final(a, reply.goal_id)
    elapsed = time.monotonic() - began
    assert end.state == "SUCCEEDED" and end.progress == 1.0
    assert elapsed >= 0.8 * 0.9, elapsed  # played in real time, not skipped
    mine = [s for s in a.status.messages if s.goal_id == reply.goal_id]
    assert [s.state for s in mine][:2] == ["ACCEPTED", "PLAYING"]
    progress = [s.progress for s in mine if s.state == "PLAYING"]
    assert progress == sorted(progress) and len(progress) >= 3
    busy = a.free.wait_for(lambda b: not b.data, what="device busy")
    # The goal's final status and `device_free` are two keys: wait for the device
    # to be free again after the busy flag, then check nothing came after.
    a.free.wait_for(lambda b: b.data and b.stamp_ns > busy.stamp_ns, timeout=15,
                    what="device free again")
    flags = [b.data for b in a.free.messages]
    assert flags[-2:] == [False, True], flags
    a.player.stop()  # the tap file is complete once the player exited
    assert np.array_equal(a.tap_samples(), samples)


def test_cancel_ends_playback_at_once(audio, probe, tmp_path) -> None:
    config, samples = beep_config(tmp_path, 5.0)
    a = audio(config)
    reply = send_goal(probe, "beep")
    a.status.wait_for(lambda s: s.goal_id == reply.goal_id and s.progress > 0.02,
                      what="some progress")
    cancel = probe.call(keys.PLAY_SOUND_CANCEL, m.CancelGoal(goal_id=reply.goal_id))
    handed_at_cancel = len(a.tap_samples())
    assert cancel.success, cancel
    end = final(a, reply.goal_id)
    assert end.state == "CANCELED"
    a.free.wait_for(lambda b: b.data and b.stamp_ns > end.stamp_ns - 10**9, what="free again")
    again = probe.call(keys.PLAY_SOUND_CANCEL, m.CancelGoal(goal_id=reply.goal_id))
    assert not again.success and "already ended" in again.message
    a.player.stop()
    produced = a.tap_samples()
    # Not one sample was handed to the device after the cancel was answered...
    assert len(produced) == handed_at_cancel
    # ...and what was handed over is the file's beginning, far from its end.
    assert 0 < len(produced) < samples.shape[0] // 2
    assert np.array_equal(produced, samples[: len(produced)])


def test_bad_sounds_are_refused_or_aborted_naming_the_file(audio, probe, tmp_path) -> None:
    (tmp_path / "broken.wav").write_bytes(b"RIFF....WAVEfmt " + bytes(range(200)))
    (tmp_path / "notes.txt").write_text("not audio at all\n" * 20)
    config, _ = beep_config(tmp_path, 0.3, broken="broken.wav", missing="missing.wav",
                            text="notes.txt")
    a = audio(config)
    unknown = send_goal(probe, "fanfare")
    assert not unknown.accepted and "unknown sound 'fanfare'" in unknown.message
    for sound, file, reason in [("broken", "broken.wav", "corrupt"),
                                ("missing", "missing.wav", "no such file"),
                                ("text", "notes.txt", "unsupported format '.txt'")]:
        reply = send_goal(probe, sound)
        assert reply.accepted, reply
        end = final(a, reply.goal_id)
        assert end.state == "ABORTED", end
        assert str(tmp_path / file) in end.message and reason in end.message, end.message
    direct = probe.call(keys.PLAY_FILE, m.PlayAudioFile(path=str(tmp_path / "nope.flac")))
    assert not direct.success and "no such file" in direct.message
    ok = send_goal(probe, "beep")  # still working after all that
    assert final(a, ok.goal_id).state == "SUCCEEDED"
    assert a.alive()


def test_malformed_requests_get_error_replies(audio, probe, tmp_path) -> None:
    a = audio()
    send_goal(probe, "unknown-sound")  # both services answer
    cases = [
        (keys.PLAY_SOUND, b"not json"), (keys.PLAY_SOUND, b'{"sound": 5}'),
        (keys.PLAY_SOUND, b'{"sound": ""}'), (keys.PLAY_SOUND, b'{"sound": "x", "y": 1}'),
        (keys.PLAY_SOUND_CANCEL, b"[1,2]"), (keys.PLAY_SOUND_CANCEL, b"{}"),
        (keys.PLAY_FILE, b'{"path": null}'), (keys.PLAY_FILE, b"\xff\xfe"),
        (keys.AUDIO_STOP, b'{"now": true}'), (keys.AUDIO_PAUSE, b"42"),
    ]
    for service, payload in cases:
        replies = list(probe.query(probe.key(service), payload, timeout=5))
        assert len(replies) == 1, (service.pattern, payload)
        assert not replies[0].ok, (service.pattern, payload)
        assert replies[0].payload, (service.pattern, payload)
    unknown = probe.call(keys.PLAY_SOUND_CANCEL, m.CancelGoal(goal_id="nope"))
    assert not unknown.success and "unknown goal" in unknown.message
    assert a.alive()
    assert send_goal(probe, "greeting").accepted  # the shipped sound, default config


def test_goal_refused_while_the_player_is_absent(audio, probe) -> None:
    audio(player=False)
    reply = retry_until(
        lambda: probe.call(keys.PLAY_SOUND, m.PlaySound(sound="greeting"), timeout=3),
        what="action answered")
    assert not reply.accepted and "audio player is not running" in reply.message


def test_a_new_goal_preempts_the_playing_one(audio, probe, tmp_path) -> None:
    config, _ = beep_config(tmp_path, 5.0)
    short = tone(0.3, freq=660.0)
    write_wav(tmp_path / "short.wav", short)
    a = audio(config + 'short = "short.wav"\n')
    first = send_goal(probe, "beep")
    a.status.wait_for(lambda s: s.goal_id == first.goal_id and s.state == "PLAYING")
    second = send_goal(probe, "short")
    assert second.accepted
    ended = final(a, first.goal_id)
    assert ended.state == "CANCELED" and second.goal_id in ended.message
    assert final(a, second.goal_id).state == "SUCCEEDED"
    a.player.stop()
    assert np.array_equal(a.tap_samples()[-short.shape[0]:], short)


def test_refuse_policy_refuses_while_busy(audio, probe, tmp_path) -> None:
    config, _ = beep_config(tmp_path, 5.0)
    a = audio(config, action_args=("--busy-policy", "refuse"))
    first = send_goal(probe, "beep")
    a.status.wait_for(lambda s: s.goal_id == first.goal_id and s.state == "PLAYING")
    second = send_goal(probe, "greeting")
    assert not second.accepted and "busy" in second.message
    probe.call(keys.PLAY_SOUND_CANCEL, m.CancelGoal(goal_id=first.goal_id))
    assert final(a, first.goal_id).state == "CANCELED"


@pytest.mark.skipif(shutil.which("espeak-ng") is None,
                    reason="espeak-ng not installed (scripts/test-packages.sh installs it)")
def test_a_sound_configured_as_text_is_spoken(audio, probe) -> None:
    a = audio('[audio.sounds]\nhello = "say:Hello, nice to see you"\n')
    reply = send_goal(probe, "hello")
    assert reply.accepted
    assert final(a, reply.goal_id).state == "SUCCEEDED"
    a.player.stop()
    assert np.abs(a.tap_samples()).max() > 1000


def test_player_exit_aborts_the_playing_goal(audio, probe, tmp_path) -> None:
    config, _ = beep_config(tmp_path, 5.0)
    a = audio(config)
    reply = send_goal(probe, "beep")
    a.status.wait_for(lambda s: s.goal_id == reply.goal_id and s.state == "PLAYING")
    a.player.kill()
    end = final(a, reply.goal_id)
    assert end.state == "ABORTED" and "player" in end.message
    again = retry_until(lambda: probe.call(keys.PLAY_SOUND, m.PlaySound(sound="beep")),
                        what="goal answered")
    assert not again.accepted and "not running" in again.message
    assert a.action.alive()


def test_unanswered_call_is_a_service_error(probe) -> None:
    with pytest.raises(ServiceError, match="no reply"):
        probe.call(keys.PLAY_SOUND, m.PlaySound(sound="greeting"), timeout=0.5)


def test_a_player_slow_to_answer_does_not_make_a_sound_played_through_look_cut(
    audio, probe, node_factory, tmp_path
) -> None:
    """A busy machine delays the player's reply: the 0.6 s sound has nearly
    played when the action server hears it started. Its end, 0.62 s after the
    request, is the whole sound, not a stop from outside the action."""
    config, _ = beep_config(tmp_path, 0.6)
    player = node_factory("audio-player")  # a player whose reply is late
    free = player.publisher(keys.DEVICE_FREE)
    free.put(m.Bool(stamp_ns=m.now_ns(), data=True))

    def play(req: m.PlayAudioFile) -> m.TriggerReply:
        asked = time.monotonic()
        free.put(m.Bool(stamp_ns=m.now_ns(), data=False))
        time.sleep(0.45)  # the reply crossing a busy machine
        threading.Timer(0.62 - (time.monotonic() - asked), lambda: free.put(
            m.Bool(stamp_ns=m.now_ns(), data=True))).start()
        return m.TriggerReply(success=True, message=f"playing {req.path} (0.600 s)")

    player.serve(keys.PLAY_FILE, play)
    a = audio(config, player=False)
    reply = send_goal(probe, "beep")
    assert reply.accepted, reply
    end = final(a, reply.goal_id)
    assert end.state == "SUCCEEDED", end
