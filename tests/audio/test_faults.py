"""Faults and attacks on the audio services, through a real router.

Each test makes one attack on the running robot: a router killed and
restarted, play_file asked for files outside the sounds, huge files, a
burst of goals, a huge name, a fake player token. The robot must keep
playing afterwards.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import msgspec
import psutil
import pytest

from buddybot.audio.access import REFUSAL
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.node import Node, error_text
from buddybot.tools.testing import (
    Collector,
    Process,
    Router,
    free_port,
    retry_until,
    run_service,
    stop_and_report,
)

from .conftest import Audio, beep_config, final, send_goal, tone, write_sparse_wav, write_wav

pytestmark = pytest.mark.integration

MB = 1024 * 1024


def play_until_success(probe: Node, status: Collector, sound: str,
                       timeout: float = 60.0) -> m.PlaySoundStatus:
    """Send goals until one is accepted and SUCCEEDS (the bus may still be recovering)."""
    seen: list[str] = []

    def attempt() -> m.PlaySoundStatus | None:
        try:
            reply = probe.call(keys.PLAY_SOUND, m.PlaySound(sound=sound), timeout=3)
        except ServiceError as exc:
            seen.append(str(exc))
            return None
        if not reply.accepted:
            seen.append(reply.message)
            return None
        end = status.wait_for(
            lambda s: s.goal_id == reply.goal_id and s.state in m.TERMINAL_GOAL_STATES,
            timeout=20, what=f"end of goal {reply.goal_id}")
        seen.append(f"{end.state} {end.message}")
        return end if end.state == "SUCCEEDED" else None

    try:
        return retry_until(attempt, timeout, interval=0.2, what=f"goal {sound!r} succeeded")
    except TimeoutError as exc:
        raise AssertionError(f"{exc}; answers (last 5): {seen[-5:]}") from None


def test_goals_succeed_again_after_the_router_is_killed_and_restarted(
    tmp_path: Path, log_dir: Path
) -> None:
    """After kill -9 of the router, goals must not be refused with "the audio player
    is not running" for good while the player is alive."""
    config, _ = beep_config(tmp_path, 0.3)
    cfg = tmp_path / "buddybot.toml"
    cfg.write_text(config)
    port = free_port()
    router = Router(port=port, log_dir=log_dir / "before")
    procs: list[Process] = [router]
    probe: Node | None = None
    try:
        procs += [run_service("audio-player", router.endpoint, "--config", str(cfg),
                              "--backend", "null", log_dir=log_dir),
                  run_service("audio", router.endpoint, "--config", str(cfg), log_dir=log_dir)]
        probe = Node("probe", connect=[router.endpoint])
        status = Collector(probe, keys.PLAY_SOUND_STATUS)
        play_until_success(probe, status, "beep")
        router.kill()  # SIGKILL: no goodbye to anyone
        procs.append(Router(port=port, log_dir=log_dir / "after"))
        play_until_success(probe, status, "beep")
        for _ in range(3):  # and it keeps working, first time every time
            reply = probe.call(keys.PLAY_SOUND, m.PlaySound(sound="beep"), timeout=5)
            assert reply.accepted, reply
            end = status.wait_for(
                lambda s, g=reply.goal_id: s.goal_id == g and s.state in m.TERMINAL_GOAL_STATES,
                timeout=20)
            assert end.state == "SUCCEEDED", end
        assert all(p.alive() for p in procs[1:3])
    finally:
        if probe is not None:
            probe.close()
        stop_and_report(procs)


def sound_box(tmp_path: Path) -> tuple[str, Path]:
    """A config whose one sound lives in `tmp_path/sounds` (so that folder is the
    allowed one), and a file outside it."""
    box = tmp_path / "sounds"
    box.mkdir()
    write_wav(box / "ok.wav", tone(0.2))
    write_wav(tmp_path / "outside.wav", tone(0.2))
    return '[audio.sounds]\nok = "sounds/ok.wav"\n', box


def test_play_file_refuses_everything_outside_the_sound_dirs_with_one_text(
    audio: Callable[..., Audio], probe: Node, tmp_path: Path
) -> None:
    """play_file must open no readable path outside the sound dirs, and its reply
    must not tell whether such a file exists."""
    config, box = sound_box(tmp_path)
    (box / "escape.wav").symlink_to(tmp_path / "outside.wav")
    (box / "passwd.wav").symlink_to("/etc/passwd")
    a = audio(config, action=False)

    def play(path: str) -> m.TriggerReply:
        return probe.call(keys.PLAY_FILE, m.PlayAudioFile(path=path), timeout=30)

    passwd = play("/etc/passwd")
    missing = play("/etc/no-such-file-anywhere")
    assert not passwd.success and passwd.message == REFUSAL
    assert missing == passwd  # exists or not: the same answer
    for path in [str(box / ".." / "outside.wav"), "../outside.wav", str(tmp_path / "outside.wav"),
                 str(box / "escape.wav"), "escape.wav", str(box / "passwd.wav"),
                 "/proc/self/environ", "/dev/zero", str(box), "/"]:
        assert play(path) == passwd, path
    assert play(str(box / "ok.wav")).success  # inside the folder: allowed
    assert play("ok.wav").success  # relative: looked up in the folders
    assert play("ok").success  # a configured name
    gone = play(str(box / "gone.wav"))  # inside an allowed folder a missing file is named
    assert not gone.success and "no such file" in gone.message
    assert a.alive()


def peak_rss(pid: int) -> int:
    """The process's peak resident memory (VmHWM), else its current RSS."""
    status = Path(f"/proc/{pid}/status")
    if status.exists():
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return int(psutil.Process(pid).memory_info().rss)


def test_too_long_or_too_large_files_are_refused_before_they_are_loaded(
    audio: Callable[..., Audio], probe: Node, tmp_path: Path
) -> None:
    """Refused before loading: loading first grew the player to 781 MB for a
    30-minute WAV, and a 2 GB file blocked it for 6.7 s."""
    config, box = sound_box(tmp_path)
    write_sparse_wav(box / "long.wav", 30 * 60)  # 30 min of 8 kHz mono: 14 MB
    with (box / "huge.wav").open("wb") as out:
        out.truncate(300 * MB)  # sparse: no disk space
    a = audio(config, action=False)
    assert a.player is not None
    retry_until(lambda: probe.call(keys.PLAY_FILE, m.PlayAudioFile(path="ok")).success,
                what="player answering")
    before_peak = peak_rss(a.player.pid)
    long = probe.call(keys.PLAY_FILE, m.PlayAudioFile(path="long.wav"), timeout=60)
    assert not long.success and "1800 s long" in long.message and "max_duration_s" in long.message
    huge = probe.call(keys.PLAY_FILE, m.PlayAudioFile(path="huge.wav"), timeout=60)
    assert not huge.success and "max_file_bytes" in huge.message, huge
    grown = peak_rss(a.player.pid) - before_peak
    rss = psutil.Process(a.player.pid).memory_info().rss
    print(f"player peak RSS grew {grown / MB:.1f} MB; RSS now {rss / MB:.1f} MB")
    assert grown < 40 * MB, grown  # decoding the long file would take 330 MB
    assert probe.call(keys.PLAY_FILE, m.PlayAudioFile(path="ok")).success
    assert a.alive()


def test_a_burst_of_200_goals_gets_exactly_one_answer_each(
    audio: Callable[..., Audio], probe: Node, tmp_path: Path
) -> None:
    """200 concurrent goals: not one may go without its reply."""
    config, _ = beep_config(tmp_path, 0.3)
    a = audio(config)
    send_goal(probe, "beep")
    payload = msgspec.json.encode(m.PlaySound(sound="beep"))
    key = probe.key(keys.PLAY_SOUND)
    pending = [probe.query(key, payload, timeout=30) for _ in range(200)]  # all sent at once
    answers = [list(replies) for replies in pending]
    assert [len(x) for x in answers] == [1] * 200
    accepted: list[str] = []
    refusals: list[str] = []
    for [answer] in answers:
        if answer.ok:
            reply = msgspec.json.decode(answer.payload, type=m.PlaySoundReply)
            if reply.accepted:
                accepted.append(reply.goal_id)
            else:
                refusals.append(reply.message)
        else:
            refusals.append(error_text(answer.payload))
    print(f"{len(accepted)} accepted, {len(refusals)} refused: {sorted(set(refusals))[:3]}")
    assert accepted and all(r.startswith("busy") for r in refusals), refusals[:3]
    mine = set(accepted)  # the newest accepted one plays to its end
    a.status.wait_for(lambda s: s.goal_id in mine and s.state == "SUCCEEDED", timeout=30,
                      what="the last goal of the burst succeeded")
    assert a.alive()
    after = send_goal(probe, "beep")
    assert after.accepted and final(a, after.goal_id).state == "SUCCEEDED"
    diag = Collector(probe, keys.DIAGNOSTICS, node="audio")
    tracked = diag.wait_for(lambda d: "goals_tracked" in d.values, timeout=20)
    assert int(tracked.values["goals_tracked"]) <= 65  # bounded history, refused never kept


def test_a_huge_sound_name_is_refused_and_logged_in_one_short_line(
    audio: Callable[..., Audio], probe: Node
) -> None:
    """A 10 MB sound name must not write a 20 MB log line: the runtime refuses names
    over 256 characters and paths over 4096 at decode; whatever gets through is
    clipped in replies and logs."""
    a = audio()
    send_goal(probe, "nothing")  # both services answer
    assert a.player is not None and a.action is not None
    for name in ("x" * 60_000, "y" * 256):
        try:
            reply = probe.call(keys.PLAY_SOUND, m.PlaySound(sound=name), timeout=10)
        except ServiceError as exc:  # refused by the runtime: the error is short too
            assert len(str(exc)) < 1000
        else:
            assert not reply.accepted and "unknown sound" in reply.message
            assert len(reply.message) < 500, len(reply.message)
    for path in ("z" * 60_000, "z" * 4096, "/" + "z" * 4095, "sounds/" + "z" * 4089):
        try:
            direct = probe.call(keys.PLAY_FILE, m.PlayAudioFile(path=path), timeout=10)
        except ServiceError as exc:
            assert len(str(exc)) < 1000
        else:
            assert not direct.success and len(direct.message) < 1100, direct.message[:300]
    a.action.wait_for_output("refused goal")
    a.player.wait_for_output("cannot play")
    for proc in (a.action, a.player):
        longest = max(len(line) for line in proc.output().splitlines())
        assert longest < 1500, (proc.name, longest)
    assert a.alive()
    assert send_goal(probe, "greeting").accepted


def test_a_fake_player_token_is_reported_and_cannot_hide_the_players_death(
    audio: Callable[..., Audio], probe: Node, tmp_path: Path
) -> None:
    """Another session declaring `nodes/audio-player/<x>` must not keep goals
    waiting for a dead player."""
    config, _ = beep_config(tmp_path, 10.0)
    a = audio(config)
    assert a.player is not None and a.action is not None
    diag = Collector(probe, keys.DIAGNOSTICS, node="audio")
    first = send_goal(probe, "beep")
    a.status.wait_for(lambda s: s.goal_id == first.goal_id and s.state == "PLAYING")
    fake = probe.declare_token(
        probe.key(keys.NODES, node="audio-player", instance="f00dfeed"))
    try:
        warn = diag.wait_for(lambda d: d.level == "WARN" and "2 instances of audio-player"
                             in d.message, timeout=20, what="duplicate player reported")
        assert "f00dfeed" in warn.message and warn.values["player_instances"] == 2
        a.player.kill()  # the real one dies; the fake token stays
        end = final(a, first.goal_id, timeout=20)
        assert end.state == "ABORTED" and "stopped running" in end.message, end
        reply = probe.call(keys.PLAY_SOUND, m.PlaySound(sound="beep"), timeout=10)
        if reply.accepted:  # the fake token still says "running": the call finds no one
            late = final(a, reply.goal_id, timeout=20)
            assert late.state == "ABORTED" and "no reply" in late.message, late
        else:
            assert "not running" in reply.message, reply
        assert a.action.alive()
    finally:
        fake.close()
