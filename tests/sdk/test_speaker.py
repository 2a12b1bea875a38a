"""`buddybot.sdk.speaker`: the handle (pure), and, marked `integration`, real `audio`
and `audio-player` services on the null device: a sound plays to SUCCEEDED, a cancel
ends it CANCELED, an unknown name is refused, any text is spoken, a malformed text
raises before anything is sent; with a controller, a sound holds an "audio" lease for
its length and an operator's lease refuses it."""

from __future__ import annotations

import asyncio
import shutil
from collections.abc import Callable
from pathlib import Path, PurePosixPath

import pytest

from buddybot.audio.access import REFUSAL
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import Bot, NoService, Refused, SoundHandle, TimedOut
from buddybot.sdk.speaker import Speaker, goal_sound
from buddybot.tools.testing import Collector, Process, retry_until
from tests.audio.conftest import (  # noqa: F401 (fixture)
    Audio,
    audio,
    beep_config,
    tone,
    write_wav,
)

# --- pure ----------------------------------------------------------------------------------


def _handle() -> SoundHandle:
    return SoundHandle(Speaker.__new__(Speaker), "g1", "beep")


def test_a_handle_follows_its_goal_to_the_first_final_state() -> None:
    handle = _handle()
    handle.update(m.PlaySoundStatus(goal_id="g1", state="PLAYING", progress=0.5))
    assert (handle.state, handle.done) == ("PLAYING", False)
    with pytest.raises(TimedOut, match=r"'beep' \(goal g1\) still PLAYING after 0\.01 s"):
        handle.wait(0.01)
    handle.update(m.PlaySoundStatus(goal_id="g1", state="CANCELED", message="preempted"))
    handle.update(m.PlaySoundStatus(goal_id="g1", state="SUCCEEDED"))
    assert handle.wait(0.01) == "CANCELED" and handle.message == "preempted"


@pytest.mark.parametrize("given, goal", [
    ("greeting", "greeting"),
    ("chime.wav", "file:chime.wav"),
    ("Chime.OGG", "file:Chime.OGG"),
    ("birds/robin", "file:birds/robin"),
    ("/usr/share/sounds/a.flac", "file:/usr/share/sounds/a.flac"),
    (Path("chime"), "file:chime"),
    (PurePosixPath("../x.mp3"), "file:../x.mp3"),
    ("say:Hello there", "say:Hello there"),
    ("file:chime", "file:chime"),
    ("wav", "wav"),
])
def test_a_path_or_a_str_with_a_slash_or_an_audio_suffix_is_a_file(given: object,
                                                                   goal: str) -> None:
    assert goal_sound(given) == goal  # type: ignore[arg-type]


@pytest.mark.parametrize("bad, why", [
    ("", "1 to 256 characters"), ("x" * 257, "1 to 256"), (Path("a" * 260), "1 to 256"),
    (42, "a sound name or a file path"), (b"chime.wav", "a sound name or a file path"),
    ("file:", "no file named"), ("a\x00.wav", "non-printable"), ("say: ", "nothing to say"),
])
def test_a_malformed_sound_raises_before_anything_is_sent(bad: object, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        goal_sound(bad)  # type: ignore[arg-type]


def test_a_file_goal_refused_by_the_player_raises_refused_with_its_reason() -> None:
    handle = _handle()
    handle.update(m.PlaySoundStatus(goal_id="g1", state="ABORTED", message=REFUSAL))
    with pytest.raises(Refused) as err:
        Speaker._judged(handle, 0.01)
    assert err.value.reason == REFUSAL
    started = _handle()
    started.update(m.PlaySoundStatus(goal_id="g1", state="PLAYING"))
    Speaker._judged(started, 0.01)  # playing: no error


# --- real audio services -------------------------------------------------------------------


@pytest.fixture
def ready_audio(audio: Callable[..., Audio], probe: Node  # noqa: F811
                ) -> Callable[..., Audio]:
    """`audio`, returning once the action server answers `audio/play_sound` (the
    player's device_free alone says nothing about it; on a busy machine the action
    server can take seconds longer to declare its queryable)."""
    def start(config: str) -> Audio:
        started = audio(config)
        retry_until(lambda: any(i.node == "audio" and "audio/play_sound" in i.services
                                for i in probe.node_infos(1.0)),
                    30, 0.2, "the audio action server answering")
        return started
    return start


@pytest.mark.integration
def test_a_sound_plays_to_its_end(ready_audio: Callable[..., Audio],
                                  bot_factory: Callable[..., Bot], tmp_path: Path) -> None:
    config, _ = beep_config(tmp_path, 0.4)
    ready_audio(config)
    bot = bot_factory()
    handle = bot.play("beep")
    assert handle.wait(30) == "SUCCEEDED", handle.message

    async def again() -> str:
        return await bot.play("beep")

    assert asyncio.run(again()) == "SUCCEEDED"


@pytest.mark.integration
def test_a_canceled_sound_ends_canceled(ready_audio: Callable[..., Audio],
                                        bot_factory: Callable[..., Bot], tmp_path: Path) -> None:
    config, _ = beep_config(tmp_path, 10.0)
    a = ready_audio(config)
    bot = bot_factory()
    handle = bot.play("beep")
    a.status.wait_for(lambda s: s.goal_id == handle.goal_id and s.state == "PLAYING",
                      what="PLAYING")
    assert handle.cancel(30) == "CANCELED" and handle.done


@pytest.mark.integration
def test_unknown_sounds_are_refused_and_bad_texts_raise_with_the_reason(
        ready_audio: Callable[..., Audio], bot_factory: Callable[..., Bot],
        tmp_path: Path) -> None:
    config, _ = beep_config(tmp_path, 0.3)
    ready_audio(config)
    bot = bot_factory()
    with pytest.raises(Refused, match="unknown sound 'fanfare'"):
        bot.play("fanfare")
    for bad, why in (("", "nothing to say"), ("x" * 241, "at most 240"),
                     ("bell\x07", "non-printable"), (42, "speaks a str")):
        with pytest.raises(ValueError, match=why):
            bot.say(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="1 to 256 characters"):
        bot.play("")


@pytest.mark.integration
def test_a_file_of_the_sound_dirs_plays_and_one_outside_is_refused_with_the_players_reason(
        ready_audio: Callable[..., Audio], bot_factory: Callable[..., Bot],
        tmp_path: Path) -> None:
    config, _ = beep_config(tmp_path, 0.3)  # the sound dirs: beep.wav's folder (tmp_path)
    write_wav(tmp_path / "chime.wav", tone(0.3))
    outside = write_wav(tmp_path.parent / f"{tmp_path.name}-outside.wav", tone(0.3))
    (tmp_path / "escape.wav").symlink_to(outside)
    a = ready_audio(config)
    bot = bot_factory()
    try:
        for sound in ("chime.wav", tmp_path / "chime.wav"):
            handle = bot.play(sound)
            assert handle.sound == "file:" + str(sound) and handle.state in (
                "PLAYING", "SUCCEEDED")
            assert handle.wait(30) == "SUCCEEDED", handle.message
        for bad in ("../../etc/passwd", "/etc/passwd", outside, "escape.wav",
                    f"../{tmp_path.name}-outside.wav", Path("."), "/no/such.wav"):
            with pytest.raises(Refused) as err:
                bot.play(bad)
            assert err.value.reason == REFUSAL, bad
        (tmp_path / "sub").mkdir()
        with pytest.raises(Refused, match="not a regular file"):
            bot.play(Path("sub"))  # a folder inside the sound dirs: the player says so
        assert bot.play("beep").wait(30) == "SUCCEEDED"  # names are still names
        assert a.alive()
    finally:
        outside.unlink()


@pytest.mark.integration
def test_a_configured_and_any_other_text_are_spoken(ready_audio: Callable[..., Audio],
                                     bot_factory: Callable[..., Bot], tmp_path: Path) -> None:
    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng is not installed (scripts/test-packages.sh installs it)")
    config, _ = beep_config(tmp_path, 0.3, hi="say:Hi")
    ready_audio(config)
    bot = bot_factory()
    handle = bot.say("Hi")
    assert handle.sound == "say:Hi" and handle.wait(60) == "SUCCEEDED", handle.message
    any_text = bot.say("Any text at all, not configured anywhere")
    assert any_text.wait(60) == "SUCCEEDED", any_text.message


@pytest.mark.integration
def test_without_an_audio_service_play_says_so(bot_factory: Callable[..., Bot]) -> None:
    bot = bot_factory(timeout=0.5)
    with pytest.raises(NoService, match=r"nobody answered on audio/play_sound within 0\.5 s"):
        bot.play("greeting")


@pytest.mark.integration
def test_a_sound_holds_the_speaker_for_its_length_and_an_operator_refuses_it(
        ready_audio: Callable[..., Audio], controller: Callable[[], Process],
        bot_factory: Callable[..., Bot], probe: Node, tmp_path: Path,
        operator_secret: str) -> None:
    config, _ = beep_config(tmp_path, 0.4)
    ready_audio(config)
    controller()
    state = Collector[m.Leases](probe, keys.LEASES)
    bot = bot_factory(name="player_app")
    with (bot_factory(name="wizard").lease("audio", priority="operator",
                                           credential=operator_secret),
          pytest.raises(Refused, match="audio is held by wizard at priority operator")):
        bot.play("beep")
    handle = bot.play("beep")
    assert handle.lease is not None and handle.lease.resources == ("audio",)
    assert handle.wait(30) == "SUCCEEDED", handle.message
    state.wait_for(lambda s: any(e.lease_id == handle.lease.lease_id  # type: ignore[union-attr]
                                 and e.reason == "released" for e in s.ended),
                   10, "the sound's lease released at its end")
    with bot.lease("audio") as mine:  # a lease of the program's own: no second one
        held = bot.play("beep")
        assert held.lease is None and held.wait(30) == "SUCCEEDED" and mine.active
