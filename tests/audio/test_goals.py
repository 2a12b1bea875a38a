"""The play_sound goal state machine, without processes."""

from __future__ import annotations

import pytest

from buddybot.audio.goals import END_TOLERANCE_S, LATE_GRACE_S, GoalBook


def states(statuses: list) -> list[tuple[str, str]]:
    return [(s.goal_id, s.state) for s in statuses]


def book(policy: str = "preempt") -> GoalBook:
    return GoalBook({"greeting", "farewell"}, policy)


def test_goal_lifecycle_accepted_playing_succeeded() -> None:
    b = book()
    d = b.request("g1", "greeting", player_present=True)
    assert d.accepted and d.reply.goal_id == "g1"
    assert states(d.statuses) == [("g1", "ACCEPTED")]
    assert b.should_play("g1")
    playing = b.started("g1", 2.0, asked_at=10.0)
    assert states(playing) == [("g1", "PLAYING")] and not b.should_play("g1")
    tick = b.tick(now=11.0)
    assert tick[0].state == "PLAYING" and tick[0].progress == pytest.approx(0.5)
    assert b.tick(now=15.0, device_free=False)[0].progress == pytest.approx(0.99)
    done = b.device_free(now=12.0)
    assert states(done) == [("g1", "SUCCEEDED")] and done[0].progress == 1.0
    assert b.active is None and b.get("g1").state == "SUCCEEDED"
    assert b.device_free(now=13.0) == [] and b.tick(now=13.0) == []


def test_unknown_sound_and_missing_player_are_refused() -> None:
    b = book()
    d = b.request("g1", "fanfare", player_present=True)
    assert not d.accepted and "unknown sound 'fanfare'" in d.reply.message
    assert "farewell, greeting" in d.reply.message and d.statuses == []
    d = b.request("g2", "greeting", player_present=False)
    assert not d.accepted and "not running" in d.reply.message
    assert b.active is None


def test_a_say_goal_speaks_any_text_and_a_bad_text_is_refused_with_why() -> None:
    b = book()
    d = b.request("g1", "say:Hello, how are you?", player_present=True)
    assert d.accepted and states(d.statuses) == [("g1", "ACCEPTED")]
    assert b.should_play("g1")
    for bad, why in (("say: ", "nothing to say"), ("say:" + "x" * 300, "at most 240"),
                     ("say:a\tb", "non-printable")):
        refused = b.request("g9", bad, player_present=True)
        assert not refused.accepted and why in refused.reply.message, refused.reply.message
    assert b.active is not None and b.active.goal_id == "g1"
    assert "say:TEXT" in b.request("g8", "fanfare", player_present=True).reply.message


def test_a_file_goal_is_left_to_the_players_sandbox_and_a_bad_path_refused_with_why() -> None:
    b = book()
    for path in ("file:chime.wav", "file:../../etc/passwd"):  # the player decides
        d = b.request(f"g-{path}", path, player_present=True)
        assert d.accepted and b.should_play(f"g-{path}"), d.reply.message
    for bad, why in (("file:", "no file named"), ("file:a\x00b", "non-printable")):
        refused = b.request("g9", bad, player_present=True)
        assert not refused.accepted and why in refused.reply.message, refused.reply.message
    assert "file:PATH" in b.request("g8", "fanfare", player_present=True).reply.message


def test_preempt_cancels_the_running_goal_first() -> None:
    b = book("preempt")
    b.request("g1", "greeting", player_present=True)
    b.started("g1", 2.0, asked_at=0.0)
    d = b.request("g2", "farewell", player_present=True)
    assert d.accepted
    assert states(d.statuses) == [("g1", "CANCELED"), ("g2", "ACCEPTED")]
    assert "preempted by goal g2" in d.statuses[0].message
    assert b.active.goal_id == "g2"


def test_refuse_policy_refuses_while_busy_also_when_someone_else_plays() -> None:
    b = book("refuse")
    b.request("g1", "greeting", player_present=True)
    d = b.request("g2", "farewell", player_present=True)
    assert not d.accepted and "busy" in d.reply.message and "g1" in d.reply.message
    b.device_free(now=0.0)  # still ACCEPTED: a stale "free" is ignored
    assert b.active.goal_id == "g1"
    b.failed("g1", "x")
    d = b.request("g3", "farewell", player_present=True, player_busy=True)
    assert not d.accepted and "another sound" in d.reply.message


def test_failure_aborts_with_the_players_reason() -> None:
    b = book()
    b.request("g1", "greeting", player_present=True)
    out = b.failed("g1", "/x/greeting.wav: no such file")
    assert states(out) == [("g1", "ABORTED")] and "no such file" in out[0].message
    assert b.failed("g1", "again") == [] and b.started("g1", 1.0, asked_at=0.0) == []


def test_cancel_active_unknown_and_finished_goals() -> None:
    b = book()
    b.request("g1", "greeting", player_present=True)
    b.started("g1", 2.0, asked_at=0.0)
    res = b.cancel("g1")
    assert res.reply.success and res.stop_player
    assert states(res.statuses) == [("g1", "CANCELED")]
    again = b.cancel("g1")
    assert not again.reply.success and "already ended (CANCELED)" in again.reply.message
    assert not again.stop_player
    unknown = b.cancel("nope")
    assert not unknown.reply.success and "unknown goal" in unknown.reply.message


def test_cancel_before_the_player_started_it_skips_playback() -> None:
    b = book()
    b.request("g1", "greeting", player_present=True)
    b.cancel("g1")
    assert not b.should_play("g1")
    assert b.started("g1", 1.0, asked_at=0.0) == []


def test_device_free_long_before_the_end_means_stopped_from_outside() -> None:
    b = book()
    b.request("g1", "greeting", player_present=True)
    b.started("g1", 3.0, asked_at=100.0)
    out = b.device_free(now=100.5)
    assert states(out) == [("g1", "CANCELED")] and "outside" in out[0].message
    b.request("g2", "greeting", player_present=True)
    b.started("g2", 3.0, asked_at=200.0)
    assert states(b.device_free(now=203.0 - END_TOLERANCE_S / 2)) == [("g2", "SUCCEEDED")]


def test_a_free_stamped_before_the_player_was_asked_is_not_the_goals_end() -> None:
    """A player that just started sends its latched "free" late, after the reply."""
    b = book()
    b.request("g1", "greeting", player_present=True)
    b.started("g1", 3.0, asked_at=100.0, asked_ns=5_000)
    assert b.device_free(now=100.1, stamp_ns=4_999) == []
    assert b.active is not None and b.active.state == "PLAYING"
    out = b.device_free(now=100.2, stamp_ns=5_001)
    assert states(out) == [("g1", "CANCELED")]


def test_free_sample_that_raced_ahead_of_the_reply_still_ends_the_goal() -> None:
    b = book()
    b.request("g1", "greeting", player_present=True)
    b.started("g1", 1.0, asked_at=0.0)
    assert b.tick(now=1.0 + LATE_GRACE_S / 2, device_free=True)[0].state == "PLAYING"
    assert b.tick(now=1.0 + LATE_GRACE_S * 2, device_free=True)[0].state == "SUCCEEDED"


def test_player_lost_aborts_and_unknown_duration_keeps_progress_zero() -> None:
    b = book()
    assert b.player_lost() == []
    b.request("g1", "greeting", player_present=True)
    b.started("g1", None, asked_at=0.0)
    assert b.tick(now=5.0)[0].progress == 0.0
    assert states(b.player_lost()) == [("g1", "ABORTED")]


def test_history_is_bounded_and_policy_checked() -> None:
    b = GoalBook({"s"}, "preempt", history=3)
    for i in range(6):
        b.request(f"g{i}", "s", player_present=True)
    assert b.get("g0") is None and b.get("g4").state == "CANCELED"
    with pytest.raises(ValueError):
        GoalBook({"s"}, "queue")


def test_a_flood_of_goals_keeps_the_book_bounded_and_refusals_untracked() -> None:
    b = GoalBook({"greeting"}, "preempt", history=8)
    for i in range(1000):
        assert b.request(f"g{i}", "greeting", player_present=True).accepted
    assert b.tracked == 9 and b.active is not None and b.active.goal_id == "g999"
    r = GoalBook({"greeting"}, "refuse", history=8)
    assert r.request("first", "greeting", player_present=True).accepted
    for i in range(1000):
        d = r.request(f"r{i}", "greeting", player_present=True)
        assert not d.accepted and "busy" in d.reply.message and d.statuses == []
        r.request(f"u{i}", "x" * 10_000, player_present=True)
    assert r.tracked == 1 and r.get("r5") is None


def test_a_huge_sound_name_is_clipped_in_the_refusal() -> None:
    d = book().request("g1", "x" * 60_000, player_present=True)
    assert not d.accepted and len(d.reply.message) < 500 and "+59800 chars" in d.reply.message


def test_player_lost_aborts_the_active_goal_with_the_reason() -> None:
    b = book()
    b.request("g1", "greeting", player_present=True)
    b.started("g1", 2.0, asked_at=1.0)
    lost = b.player_lost("the audio player that was playing it (abc) stopped running")
    assert states(lost) == [("g1", "ABORTED")] and "(abc)" in lost[0].message
    assert b.player_lost() == []
