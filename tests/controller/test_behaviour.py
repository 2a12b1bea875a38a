"""Unit tests of the pure behaviour, driven by a fake clock: every transition, and the
state it reports on `controller/state` (why it waits, its visits). When the controller
publishes that state, and the message it becomes: test_service.py."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.contract.messages import ExpressionAction as X
from buddybot.controller.behaviour import (
    Behaviour,
    CancelSound,
    Command,
    Look,
    Phase,
    PlaySound,
    SetExpression,
    SoundKind,
    State,
)
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze

GAZE = Gaze(0.1, -0.05, 120.0)
FACE_TIMEOUT_S = 0.5
"""The people service's default `face_timeout_s`: a face older than this is not shown."""


class Rig:
    """A behaviour, a fake clock and the commands it gave, for readable tests."""

    def __init__(self, face_timeout_s: float = FACE_TIMEOUT_S, **overrides: object) -> None:
        # Straight to drowsy after a departure (the alone phase has tests of its own).
        params: dict[str, object] = {"recover_s": 0.0, "alone_s": 0.0}
        params.update(overrides)
        self.s = msgspec.convert(params, ControllerSettings)
        self.t = 1000.0
        self.b = Behaviour(self.s, self.t)
        self.log: list[tuple[float, Command]] = []
        self.goal = 0
        # The people service's part: who is in range, and whether it shows their face.
        self.face_timeout_s = face_timeout_s
        self.said: tuple[bool, int | None, str | None] | None = None
        self.last_face: float | None = None
        self.face_shown = False

    def _rec(self, cmds: list[Command]) -> list[Command]:
        self.log.extend((self.t, c) for c in cmds)
        return cmds

    def at(self, dt: float) -> list[Command]:
        """Advance the clock by `dt` in ticks of 50 ms; returns what came out."""
        out: list[Command] = []
        end = self.t + dt
        while self.t < end - 1e-9:
            self.t = min(end, self.t + 0.05)
            out += self.people_face()
            out += self._rec(self.b.tick(self.t))
        return out

    def presence(self, in_range: bool, person_id: int | None = None,
                 name: str | None = None) -> list[Command]:
        self.said = (in_range, person_id, name)
        return self._rec(self.b.presence(self.t, in_range, person_id, name,
                                         face=self.face_shown))

    def face(self, gaze: Gaze = GAZE, stamp_ns: int | None = 42) -> list[Command]:
        """A face: the gaze's fast path, then the people service's state showing it."""
        self.last_face = self.t
        return self._rec(self.b.face(self.t, gaze, stamp_ns)) + self.people_face()

    def people_face(self) -> list[Command]:
        """What the people service says of the face when that changes: shown while
        one came within `face_timeout_s` (its `[people] face_timeout_s`)."""
        shown = self.last_face is not None and self.t - self.last_face <= self.face_timeout_s
        if shown == self.face_shown:
            return []
        self.face_shown = shown
        if self.said is None:
            return []  # no people state yet: only the gaze
        in_range, person_id, name = self.said
        return self._rec(self.b.presence(self.t, in_range, person_id, name, face=shown))

    def faces(self, seconds: float, period: float = 0.1) -> list[Command]:
        out: list[Command] = []
        end = self.t + seconds
        while self.t < end - 1e-9:
            out += self.face()
            out += self.at(period)
        return out

    def device_free(self, free: bool) -> list[Command]:
        return self._rec(self.b.device_free(self.t, free))

    def speaker_blocked(self, by: str, blocked: bool) -> list[Command]:
        """`device busy` (audio/device_free false) or a `lease on the speaker`."""
        if by == "device busy":
            return self.device_free(not blocked)
        return self._rec(self.b.audio_held(self.t, blocked))

    def accept(self, cmd: PlaySound) -> str:
        self.goal += 1
        gid = f"g{self.goal}"
        self._rec(self.b.sound_reply(self.t, cmd.request, True, gid))
        return gid

    def status(self, gid: str, state: str, age: float | None = None) -> list[Command]:
        return self._rec(self.b.sound_status(self.t, gid, state, age))

    def sounds(self) -> list[str]:
        return [c.sound for _, c in self.log if isinstance(c, PlaySound)]

    def expressions(self) -> list[X]:
        return [c.action for _, c in self.log if isinstance(c, SetExpression)]

    def last(self, kind: type) -> Command:
        return [c for _, c in self.log if isinstance(c, kind)][-1]


def plays(cmds: list[Command]) -> list[PlaySound]:
    return [c for c in cmds if isinstance(c, PlaySound)]


def test_idle_at_start_publishes_sleep_once() -> None:
    r = Rig()
    r.at(1.0)
    assert r.expressions() == [X.EYE_SLEEP]
    assert r.b.phase(r.t) is Phase.IDLE


def test_in_range_opens_eyes_at_once() -> None:
    r = Rig()
    r.at(0.1)
    out = r.presence(True)
    assert SetExpression(X.EYE_AWAKE) in out
    assert r.b.phase(r.t) is Phase.NOTICED


def test_same_presence_again_does_not_repeat_expression() -> None:
    r = Rig()
    r.presence(True)
    r.presence(True)
    r.at(0.5)
    assert r.expressions() == [X.EYE_AWAKE]


def test_face_is_looked_at_immediately_with_its_stamp() -> None:
    r = Rig()
    out = r.face()
    assert out[0] == Look(GAZE, 42)


def test_face_makes_engaged_and_greets_after_dwell() -> None:
    r = Rig(greet_dwell_s=1.0)
    r.presence(True)
    r.faces(0.9)
    assert r.sounds() == []
    assert r.b.phase(r.t) is Phase.ENGAGED
    r.faces(0.3)
    assert r.sounds() == ["greeting"]
    assert r.expressions()[-1] == X.EYE_GRIN


@pytest.mark.parametrize(("name", "settings", "sound"), [
    (None, {"greeting_named": "say:Hello {name}"}, "greeting"),
    ("Ada", {}, "greeting"),
    ("Ada", {"greeting_named": "say:Hello {name}"}, "say:Hello Ada"),
    ("Ada", {"greeting_named": "say:Hello {name}", "greetings": {"Ada": "hello_ada"}},
     "hello_ada"),
    ("Grace", {"greeting_named": "say:Hi {name}!", "greetings": {"Ada": "hello_ada"}},
     "say:Hi Grace!"),
    ("Grace", {"greeting_named": "hi-{name}"}, "hi-Grace"),
    ("Bad\x07", {"greeting_named": "say:Hello {name}"}, "greeting"),  # not speakable
    ("x" * 64, {"greeting_named": "say:" + "y" * 200 + "{name}"}, "greeting"),  # too long
])
def test_the_greeting_uses_the_persons_name(name: str | None, settings: dict[str, object],
                                            sound: str) -> None:
    r = Rig(greet_dwell_s=0.5, **settings)
    r.presence(True, 1, name)
    r.faces(0.7)
    assert r.sounds() == [sound]


def test_the_name_is_the_one_at_greeting_time() -> None:
    r = Rig(greet_dwell_s=1.0, greeting_named="say:Hello {name}")
    r.presence(True, 1)
    r.faces(0.5)
    r.presence(True, 1, "Ada")  # recognised during the dwell
    r.faces(0.7)
    assert r.sounds() == ["say:Hello Ada"]


def test_a_name_forgotten_before_the_greeting_is_not_said() -> None:
    r = Rig(greet_dwell_s=1.0, greeting_named="say:Hello {name}")
    r.presence(True, 1, "Ada")
    r.faces(0.5)
    r.presence(True, 1, None)  # erased: people/state without the name
    r.faces(0.7)
    assert r.sounds() == ["greeting"]


def test_passer_by_is_not_greeted() -> None:
    r = Rig(greet_dwell_s=1.5, farewell_delay_s=0.5)
    r.presence(True)
    r.faces(0.8)
    r.presence(False)
    r.at(5.0)
    assert r.sounds() == []
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_SLEEPY, X.EYE_SLEEP]


def test_face_without_radar_is_not_greeted() -> None:
    r = Rig()
    r.faces(5.0)
    assert r.sounds() == []


def test_grin_while_greeting_then_awake() -> None:
    r = Rig(greet_dwell_s=0.0)
    r.presence(True)
    out = r.face()
    (cmd,) = plays(out)
    gid = r.accept(cmd)
    r.status(gid, "PLAYING")
    r.faces(0.3)
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_GRIN]
    r.status(gid, "SUCCEEDED")
    r.faces(0.2)
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_GRIN, X.EYE_AWAKE]


def test_leave_after_greeting_plays_farewell_then_sleepy_then_sleep() -> None:
    r = Rig(greet_dwell_s=0.5, farewell_delay_s=1.0, sleepy_s=2.0)
    r.presence(True)
    r.faces(1.0)
    gid = r.accept(r.last(PlaySound))  # type: ignore[arg-type]
    r.status(gid, "SUCCEEDED")
    r.faces(1.0)
    r.presence(False)
    r.at(0.9)
    assert r.sounds() == ["greeting"]  # absence hold not over yet
    assert r.b.phase(r.t) is Phase.LEAVING
    r.at(0.2)
    assert r.sounds() == ["greeting", "farewell"]
    assert r.b.phase(r.t) is Phase.DROWSY
    fid = r.accept(r.last(PlaySound))  # type: ignore[arg-type]
    r.at(3.0)
    assert r.expressions()[-1] == X.EYE_SLEEPY  # still saying goodbye
    r.status(fid, "SUCCEEDED")
    r.at(0.1)
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_GRIN, X.EYE_AWAKE, X.EYE_SLEEPY, X.EYE_SLEEP]


def test_alone_after_the_visit_awake_then_looking_around_then_drowsy_then_asleep() -> None:
    """Nobody left: awake while the goodbye plays, then looking around until
    `alone_s` after the departure, drowsy for `sleepy_s`, asleep."""
    r = Rig(greet_dwell_s=0.5, alone_s=4.0, sleepy_s=2.0)
    r.presence(True)
    r.faces(1.0)
    r.status(r.accept(r.last(PlaySound)), "SUCCEEDED")  # type: ignore[arg-type]
    r.presence(False)
    r.at(0.1)
    left = r.t
    assert r.b.phase(r.t) is Phase.ALONE and r.sounds() == ["greeting", "farewell"]
    fid = r.accept(r.last(PlaySound))  # type: ignore[arg-type]
    r.at(1.0)
    assert r.expressions()[-1] == X.EYE_AWAKE  # saying goodbye
    r.status(fid, "SUCCEEDED")
    r.at(0.1)
    assert r.expressions()[-1] == X.EYE_LOOK_RANDOM
    r.at(left + 4.0 - r.t + 0.05)
    assert r.b.phase(r.t) is Phase.DROWSY and r.expressions()[-1] == X.EYE_SLEEPY
    r.at(2.0)
    assert r.b.phase(r.t) is Phase.IDLE
    assert r.expressions()[-3:] == [X.EYE_LOOK_RANDOM, X.EYE_SLEEPY, X.EYE_SLEEP]
    assert r.b.state(r.t).phase is Phase.IDLE
    # Someone arriving while it is alone wakes it at once.
    r2 = Rig(greet_dwell_s=0.5, alone_s=4.0)
    r2.presence(True)
    r2.presence(False)
    r2.at(1.0)
    assert r2.b.phase(r2.t) is Phase.ALONE
    r2.presence(True)
    assert r2.b.phase(r2.t) is Phase.NOTICED


def test_no_farewell_without_greeting() -> None:
    r = Rig(greet_dwell_s=10.0)
    r.presence(True)
    r.faces(2.0)
    r.presence(False)
    r.at(10.0)
    assert r.sounds() == []


def test_radar_flicker_is_absorbed() -> None:
    r = Rig(greet_dwell_s=0.5, farewell_delay_s=1.0)
    r.presence(True)
    r.faces(1.0)
    gid = r.accept(r.last(PlaySound))  # type: ignore[arg-type]
    r.status(gid, "SUCCEEDED")
    for _ in range(10):
        r.presence(False)
        r.faces(0.3)
        r.presence(True)
        r.faces(0.3)
    assert r.sounds() == ["greeting"]
    assert X.EYE_SLEEPY not in r.expressions()
    assert X.EYE_SLEEP not in r.expressions()


def test_quick_walk_away_cancels_greeting_then_farewell() -> None:
    r = Rig(greet_dwell_s=0.0, farewell_delay_s=0.5)
    r.presence(True)
    cmd = plays(r.face())[0]
    gid = r.accept(cmd)
    r.status(gid, "PLAYING")
    r.device_free(False)
    r.presence(False)
    out = r.at(0.6)
    assert CancelSound(gid) in out
    assert plays(out) == []  # not before the greeting has stopped
    r.at(0.5)
    assert r.sounds() == ["greeting"]
    r.status(gid, "CANCELED")
    assert r.sounds() == ["greeting"]  # device still busy
    out = r.device_free(True)
    assert [p.sound for p in plays(out)] == ["farewell"]


def test_cancel_waits_for_goal_id_when_reply_is_late() -> None:
    r = Rig(greet_dwell_s=0.0, farewell_delay_s=0.0)
    r.presence(True)
    cmd = plays(r.face())[0]
    r.presence(False)
    assert not any(isinstance(c, CancelSound) for _, c in r.log)
    r._rec(r.b.sound_reply(r.t, cmd.request, True, "late"))
    assert isinstance(r.log[-1][1], CancelSound)


def test_status_before_reply_is_not_lost() -> None:
    r = Rig(greet_dwell_s=0.0)
    r.presence(True)
    cmd = plays(r.face())[0]
    r.status("g1", "SUCCEEDED")  # the audio server was faster than its reply
    r.accept(cmd)
    assert not r.b.sound_busy()


def test_refused_greeting_means_no_farewell_and_no_retry_within_cooldown() -> None:
    r = Rig(greet_dwell_s=0.0, regreet_cooldown_s=10.0, farewell_delay_s=0.0)
    r.presence(True)
    cmd = plays(r.face())[0]
    r._rec(r.b.sound_reply(r.t, cmd.request, False))
    r.faces(5.0)
    assert r.sounds() == ["greeting"]
    r.presence(False)
    r.at(6.0)
    assert r.sounds() == ["greeting"]


def test_busy_device_delays_greeting() -> None:
    r = Rig(greet_dwell_s=0.0)
    r.device_free(False)
    r.presence(True)
    r.faces(2.0)
    assert r.sounds() == []
    r.device_free(True)
    r.faces(0.2)
    assert r.sounds() == ["greeting"]


@pytest.mark.parametrize("blocker", ["device busy", "lease on the speaker"])
@pytest.mark.parametrize(("blocked_s", "played"), [(1.0, True), (3.0, False)])
def test_a_farewell_waits_for_the_speaker_then_plays_or_is_dropped(
        blocker: str, blocked_s: float, played: bool) -> None:
    r = Rig(greet_dwell_s=0.0, farewell_delay_s=0.0, farewell_max_delay_s=2.0)
    r.presence(True)
    gid = r.accept(plays(r.face())[0])
    r.status(gid, "SUCCEEDED")
    r.speaker_blocked(blocker, True)  # someone else plays something, or holds the speaker
    r.presence(False)
    r.at(blocked_s)
    r.speaker_blocked(blocker, False)
    r.at(1.0)
    assert r.sounds() == (["greeting", "farewell"] if played else ["greeting"])
    assert r.b.counters["farewells_dropped"] == (0 if played else 1)


def test_a_held_speaker_delays_the_greeting_and_says_why() -> None:
    r = Rig(greet_dwell_s=0.0)
    r.speaker_blocked("lease on the speaker", True)
    r.presence(True)
    r.faces(2.0)
    assert r.sounds() == []
    assert r.b.state(r.t).waiting == "yielded"
    assert r.expressions()[-1] == X.EYE_AWAKE  # only the sound waits
    r.speaker_blocked("lease on the speaker", False)
    assert r.sounds() == ["greeting"]


def greeted_and_farewelled(r: Rig) -> None:
    """Someone comes, is greeted at once and leaves: both sounds played to their end
    (a rig without greeting dwell nor absence hold)."""
    r.presence(True)
    gid = r.accept(plays(r.face())[0])
    r.status(gid, "SUCCEEDED")
    r.presence(False)
    fid = r.accept(r.last(PlaySound))  # type: ignore[arg-type]
    r.status(fid, "SUCCEEDED")


def test_back_within_cooldown_is_same_visit() -> None:
    r = Rig(greet_dwell_s=0.0, farewell_delay_s=0.0, regreet_cooldown_s=10.0)
    greeted_and_farewelled(r)
    r.at(3.0)
    r.presence(True)
    r.faces(3.0)
    r.presence(False)
    r.at(3.0)
    assert r.sounds() == ["greeting", "farewell"]


def test_back_after_cooldown_is_a_new_visit() -> None:
    r = Rig(greet_dwell_s=0.0, farewell_delay_s=0.0, regreet_cooldown_s=5.0)
    greeted_and_farewelled(r)
    r.at(6.0)
    r.presence(True)
    r.faces(0.5)
    assert r.sounds() == ["greeting", "farewell", "greeting"]


def test_coming_back_before_the_farewell_started_cancels_it() -> None:
    r = Rig(greet_dwell_s=0.0, farewell_delay_s=0.0)
    r.presence(True)
    gid = r.accept(plays(r.face())[0])
    r.status(gid, "PLAYING")
    r.presence(False)  # cancel sent, farewell waits
    r.presence(True)
    r.status(gid, "CANCELED")
    r.faces(1.0)
    assert r.sounds() == ["greeting"]
    r.presence(False)  # the visit goes on: the farewell is owed once
    r.at(0.1)
    assert r.sounds() == ["greeting", "farewell"]


def test_face_lost_holds_gaze_then_centres_once() -> None:
    r = Rig(gaze_hold_s=1.0)
    r.face()
    out = r.at(0.9)
    assert not any(isinstance(c, Look) for c in out)
    out = r.at(0.2)
    assert [c for c in out if isinstance(c, Look)] == [Look(None)]
    assert not any(isinstance(c, Look) for c in r.at(3.0))


def test_present_without_face_looks_around_then_awake_on_face() -> None:
    r = Rig(look_around_after_s=2.0)
    r.presence(True)
    r.at(1.9)
    assert r.expressions() == [X.EYE_AWAKE]
    r.at(0.2)
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_LOOK_RANDOM]
    r.face()
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_LOOK_RANDOM, X.EYE_AWAKE]


def test_face_occlusion_short_keeps_awake_long_looks_around() -> None:
    r = Rig(greet_dwell_s=0.0, look_around_after_s=2.0)
    r.presence(True)
    gid = r.accept(plays(r.face())[0])
    r.status(gid, "SUCCEEDED")
    r.faces(1.0)
    r.at(1.0)  # short occlusion
    r.faces(1.0)
    assert r.expressions() == [X.EYE_AWAKE, X.EYE_GRIN, X.EYE_AWAKE]
    r.at(3.0)
    assert r.expressions()[-1] == X.EYE_LOOK_RANDOM
    r.faces(1.0)
    assert r.sounds() == ["greeting"]


def test_look_around_can_be_disabled() -> None:
    r = Rig(look_around=False)
    r.presence(True)
    r.at(10.0)
    assert r.expressions() == [X.EYE_AWAKE]


def test_lost_sound_is_forgotten_after_timeout() -> None:
    r = Rig(greet_dwell_s=0.0, sound_timeout_s=5.0)
    r.presence(True)
    r.accept(plays(r.face())[0])
    r.faces(5.5)
    assert not r.b.sound_busy()
    assert r.b.counters["sounds_lost"] == 1


def test_seed_mode_all_timings_zero() -> None:
    zero = {k: 0.0 for k in ("farewell_delay_s", "gaze_hold_s",
                             "look_around_after_s", "greet_dwell_s", "regreet_cooldown_s",
                             "alone_s", "sleepy_s")}
    r = Rig(look_around=False, **zero)
    r.presence(True)
    assert r.expressions() == [X.EYE_AWAKE]
    cmd = plays(r.face())
    assert [c.sound for c in cmd] == ["greeting"]
    gid = r.accept(cmd[0])
    r.status(gid, "SUCCEEDED")
    out = r.presence(False)
    assert SetExpression(X.EYE_SLEEP) in out
    assert [c.sound for c in plays(out)] == ["farewell"]


# --- restart recovery ------------------------------------------------------------------


def test_recovery_waits_then_publishes_the_current_state_once() -> None:
    r = Rig(recover_s=0.5)
    r.presence(True)
    r.at(0.4)
    assert r.expressions() == []  # still listening to the latched inputs
    r.at(0.2)
    assert r.expressions() == [X.EYE_AWAKE]
    r.at(1.0)
    assert r.expressions() == [X.EYE_AWAKE]


def test_recovery_recent_sound_means_already_greeted() -> None:
    r = Rig(recover_s=0.5, greet_dwell_s=0.0, regreet_cooldown_s=10.0, farewell_delay_s=0.0)
    r.presence(True)
    r.status("old", "SUCCEEDED", age=2.0)
    r.faces(3.0)
    assert r.sounds() == []
    r.presence(False)  # the greeting happened before the restart: goodbye is owed
    r.at(0.1)
    assert r.sounds() == ["farewell"]


def test_recovery_listens_on_after_a_late_latched_presence() -> None:
    """On a busy machine the latched inputs can come near the end of the recovery:
    the sound status that follows the presence still counts, so no second greeting."""
    r = Rig(recover_s=0.5, greet_dwell_s=0.0, regreet_cooldown_s=10.0, farewell_delay_s=0.0)
    r.at(0.45)
    r.presence(True)
    r.at(0.3)  # past the recovery counted from the start, not from the presence
    assert state(r).waiting == "recovery"
    r.status("old", "SUCCEEDED", age=2.0)
    r.faces(3.0)
    assert r.sounds() == []
    assert r.expressions() == [X.EYE_AWAKE]


def test_recovery_arrival_after_an_empty_room_is_owed_no_farewell() -> None:
    """Nobody there at the restart, a recent sound (the last visit's farewell), and
    the visitor back during the recovery: no greeting within the cooldown, and no
    second goodbye (found by the property test once its farewell invariant held
    across restarts)."""
    r = Rig(recover_s=0.5, greet_dwell_s=0.0, regreet_cooldown_s=10.0, farewell_delay_s=0.0)
    r.presence(False)
    r.status("old", "SUCCEEDED", age=2.0)
    r.at(0.1)
    r.presence(True)
    r.faces(3.0)
    assert r.sounds() == []
    r.presence(False)
    r.at(0.1)
    assert r.sounds() == []


def test_recovery_old_sound_allows_greeting() -> None:
    r = Rig(recover_s=0.5, greet_dwell_s=0.0, regreet_cooldown_s=10.0)
    r.presence(True)
    r.status("old", "SUCCEEDED", age=60.0)
    r.faces(1.0)
    assert r.sounds() == ["greeting"]


def test_recovery_playing_sound_blocks_until_it_ends() -> None:
    r = Rig(recover_s=0.5, greet_dwell_s=0.0, regreet_cooldown_s=10.0)
    r.presence(True)
    r.status("old", "PLAYING", age=None)
    r.faces(1.0)
    assert r.b.sound_busy()
    r.status("old", "SUCCEEDED")
    r.faces(1.0)
    assert r.sounds() == []  # treated as this visit's greeting


@pytest.mark.parametrize("field", ["farewell_delay_s", "greet_dwell_s", "sleepy_s"])
def test_negative_timings_are_refused(field: str) -> None:
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert({field: -1.0}, ControllerSettings)


def test_recovery_recent_sound_while_nobody_there_still_blocks_a_quick_regreet() -> None:
    r = Rig(recover_s=0.5, greet_dwell_s=0.0, regreet_cooldown_s=10.0)
    r.presence(False)
    r.status("old", "SUCCEEDED", age=3.0)
    r.at(1.0)
    r.presence(True)
    r.faces(4.0)  # 8 s after that sound: still within the cooldown
    assert r.sounds() == []
    r.faces(3.0)
    assert r.sounds() == ["greeting"]


# --- the state it reports (`controller/state`) -----------------------------------------


def state(r: Rig) -> State:
    return r.b.state(r.t)


def greet(r: Rig) -> str:
    """Someone comes, is greeted after the dwell and the greeting is accepted: its goal id."""
    r.presence(True)
    r.faces(r.s.greet_dwell_s + 0.2)
    return r.accept(r.last(PlaySound))  # type: ignore[arg-type]


def test_the_person_of_the_visit_is_named_until_the_visit_is_over() -> None:
    """The person id is the one the radar showed last: through the greeting, while
    they leave and while the farewell plays; nobody's once the robot sleeps."""
    r = Rig(greet_dwell_s=0.5, farewell_delay_s=0.5, sleepy_s=1.0)
    assert state(r).person_id is None
    r.presence(True, person_id=3)
    assert (state(r).phase, state(r).person_id) == (Phase.NOTICED, 3)
    gid = greet(r)
    assert (state(r).greeted, state(r).person_id) == (True, 3)
    r.status(gid, "SUCCEEDED")
    r.presence(False)  # the radar lost them: the people service names nobody in range
    assert (state(r).phase, state(r).person_id) == (Phase.LEAVING, 3)
    r.at(0.6)
    farewell = r.last(PlaySound)
    assert isinstance(farewell, PlaySound) and farewell.sound == "farewell"
    assert (state(r).phase, state(r).person_id) == (Phase.DROWSY, 3)
    r.status(r.accept(farewell), "SUCCEEDED")
    r.at(1.1)
    assert (state(r).phase, state(r).person_id) == (Phase.IDLE, None)
    r.presence(True, person_id=4)  # the next visitor
    assert state(r).person_id == 4


def test_another_person_in_range_becomes_the_visits_person() -> None:
    r = Rig()
    r.presence(True, person_id=1)
    r.presence(True, person_id=2)  # nearer now: the same visit, about them
    st = state(r)
    assert (st.visit, st.person_id, st.phase) == (1, 2, Phase.NOTICED)
    assert r.expressions() == [X.EYE_AWAKE]


# --- why the controller waits ----------------------------------------------------------


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
    r = Rig(greet_dwell_s=0.5, farewell_delay_s=0.5, greeting_sound="hello")
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
    r = Rig(greet_dwell_s=0.5, farewell_delay_s=0.5, regreet_cooldown_s=0.0)
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
    r = Rig(greet_dwell_s=5.0, farewell_delay_s=1.0)
    r.presence(True)
    r.faces(0.5)
    r.presence(False)
    r.at(0.2)
    st = state(r)
    assert (st.phase, st.waiting, st.in_range) == (Phase.LEAVING, "nothing", False)


# --- visits ----------------------------------------------------------------------------


def test_visits_count_and_a_quick_return_continues_the_visit() -> None:
    r = Rig(farewell_delay_s=0.5, regreet_cooldown_s=3.0)
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
