"""`controller/state`: what the behaviour reports (pure, fake clock) and the message
it becomes. When the controller publishes it: test_controller_scenes.py."""

from __future__ import annotations

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.controller.behaviour import Phase, PlaySound, SoundKind, State
from buddybot.controller.service import state_message
from tests.controller.test_controller_behaviour import Rig


def state(r: Rig) -> State:
    return r.b.state(r.t)


def greet(r: Rig) -> str:
    """Someone comes, is greeted after the dwell and the greeting is accepted: its goal id."""
    r.presence(True)
    r.faces(r.s.greet_dwell_s + 0.2)
    return r.accept(r.last(PlaySound))  # type: ignore[arg-type]


# --- why the controller waits ------------------------------------------------------------


def test_nobody_there_waits_for_nothing() -> None:
    r = Rig()
    r.at(1.0)
    st = state(r)
    assert (st.phase, st.waiting, st.waiting_s, st.visit) == (Phase.IDLE, "nothing", 0.0, 0)
    assert not st.in_range and not st.face_visible and st.sound is None


def test_recovery_is_named_until_it_ends() -> None:
    r = Rig(recover_s=0.5)
    r.presence(True)
    assert state(r).waiting == "recovery"
    r.at(0.3)
    assert state(r).waiting == "recovery"
    r.at(0.3)
    assert state(r).waiting == "face"  # recovered: in range, no face yet


def test_noticed_without_a_face_waits_for_a_face() -> None:
    r = Rig()
    r.presence(True)
    st = state(r)
    assert (st.phase, st.waiting, st.in_range, st.face_visible) == (
        Phase.NOTICED, "face", True, False)


def test_a_face_waits_out_the_dwell_with_the_time_left() -> None:
    r = Rig(greet_dwell_s=1.0)
    r.presence(True)
    r.faces(0.3)
    first = state(r)
    assert (first.phase, first.waiting, first.face_visible) == (Phase.ENGAGED, "dwell", True)
    assert first.waiting_s == pytest.approx(0.7, abs=0.06)
    r.faces(0.3)
    later = state(r)
    assert later.waiting_s == pytest.approx(first.waiting_s - 0.3, abs=1e-6)
    assert later == first  # only the countdown moved: no news


def test_greeted_waits_until_the_farewell() -> None:
    r = Rig(greet_dwell_s=0.5)
    gid = greet(r)
    st = state(r)
    assert (st.waiting, st.greeted, st.sound) == ("greeted", True, SoundKind.GREETING)
    assert st.last_greeting_at == r.t and st.last_farewell_at is None
    r.status(gid, "SUCCEEDED")
    r.faces(1.0)
    assert (state(r).waiting, state(r).sound) == ("greeted", None)


def test_an_owed_farewell_waits_for_our_greeting_then_the_device() -> None:
    r = Rig(greet_dwell_s=0.5, absence_hold_s=0.5, greeting_sound="hello")
    gid = greet(r)  # still playing when the visitor leaves
    r.presence(False)
    r.at(0.6)
    st = state(r)
    assert (st.phase, st.farewell_pending, st.waiting) == (Phase.DROWSY, True, "sound_busy")
    r.device_free(False)  # the player says busy while it plays
    r.status(gid, "CANCELED")
    r.at(0.1)
    assert state(r).waiting == "device_busy" and r.sounds() == ["hello"]
    r.device_free(True)
    fid = r.accept(r.last(PlaySound))  # type: ignore[arg-type]
    st = state(r)
    assert r.sounds() == ["hello", "farewell"]
    assert (st.farewell_pending, st.sound, st.waiting) == (False, SoundKind.FAREWELL, "nothing")
    assert st.last_farewell_at == r.t and st.last_greeting_at is not None
    assert st.last_greeting_at < st.last_farewell_at
    r.status(fid, "SUCCEEDED")


def test_a_new_visitor_waits_while_the_last_farewell_plays() -> None:
    r = Rig(greet_dwell_s=0.5, absence_hold_s=0.5, regreet_cooldown_s=0.0)
    gid = greet(r)
    r.status(gid, "SUCCEEDED")
    r.presence(False)
    r.at(0.6)
    r.accept(r.last(PlaySound))  # type: ignore[arg-type]  # the farewell, playing
    r.presence(True)  # somebody new (no cooldown: a new visit at once)
    r.faces(1.0)
    st = state(r)
    assert (st.visit, st.greeted, st.waiting, st.sound) == (2, False, "sound_busy",
                                                             SoundKind.FAREWELL)


def test_a_busy_device_holds_back_the_greeting() -> None:
    r = Rig(greet_dwell_s=0.5)
    r.device_free(False)
    r.presence(True)
    r.faces(1.0)
    assert state(r).waiting == "device_busy" and r.sounds() == []
    r.device_free(True)
    assert r.sounds() == ["greeting"]


def test_a_sound_just_before_a_restart_holds_the_greeting_for_the_cooldown() -> None:
    r = Rig(recover_s=0.3, greet_dwell_s=0.2, regreet_cooldown_s=6.0)
    r.presence(False)  # the latched presence: nobody was there at the start
    r.status("old", "SUCCEEDED", age=2.0)  # a sound ended 2 s ago
    r.at(0.4)
    r.presence(True)
    r.faces(0.5)
    st = state(r)
    assert (st.phase, st.waiting, st.greeted) == (Phase.ENGAGED, "cooldown", False)
    assert st.waiting_s == pytest.approx(6.0 - 2.0 - 0.9, abs=0.06)
    assert st.last_greeting_at is None  # not known to have been a greeting
    r.faces(st.waiting_s + 0.1)
    assert r.sounds() == ["greeting"]


def test_a_leaving_visitor_is_not_waited_for() -> None:
    r = Rig(greet_dwell_s=5.0, absence_hold_s=1.0)
    r.presence(True)
    r.faces(0.5)
    r.presence(False)
    r.at(0.2)
    st = state(r)
    assert (st.phase, st.waiting, st.in_range) == (Phase.LEAVING, "nothing", False)


# --- visits ----------------------------------------------------------------------------


def test_visits_count_and_a_quick_return_continues_the_visit() -> None:
    r = Rig(absence_hold_s=0.5, regreet_cooldown_s=3.0)
    r.presence(True)
    assert state(r).visit == 1
    r.presence(False)
    r.at(1.0)  # departed
    r.presence(True)  # back within the cooldown: the same visit
    assert state(r).visit == 1
    r.presence(False)
    r.at(0.2)  # flicker absorbed by the absence hold: still the same visit
    r.presence(True)
    assert state(r).visit == 1
    r.presence(False)
    r.at(4.0)
    assert state(r).visit == 1  # nobody there: the count stays
    r.presence(True)
    assert state(r).visit == 2


# --- the message -------------------------------------------------------------------------


def test_the_message_has_wall_clock_times_and_is_valid() -> None:
    r = Rig(greet_dwell_s=0.5)
    greet(r)
    r.faces(0.4)
    now_ns = 1_700_000_000_000_000_000
    msg = state_message(state(r), r.t, now_ns)
    topic = keys.CONTROLLER_STATE
    back = topic.codec.decode(topic.codec.encode(msg), topic.type)  # ranges checked
    assert back == msg
    assert (msg.stamp_ns, msg.phase, msg.sound, msg.waiting) == (
        now_ns, "engaged", "greeting", "greeted")
    assert msg.expression == m.ExpressionAction.EYE_GRIN and msg.visit == 1
    assert msg.last_greeting_ns == pytest.approx(now_ns - 0.4e9, abs=0.06e9)
    assert msg.last_farewell_ns is None


def test_the_message_of_a_fresh_controller() -> None:
    msg = state_message(Rig(recover_s=0.5).b.state(1000.0), 1000.0, 5)
    assert (msg.phase, msg.waiting, msg.visit, msg.expression) == ("idle", "recovery", 0, None)


def news(s: m.ControllerState) -> tuple[object, ...]:
    """Every field but the stamp and the countdown: what a publication must change."""
    return tuple(getattr(s, f) for f in s.__struct_fields__
                 if f not in ("stamp_ns", "waiting_s"))
