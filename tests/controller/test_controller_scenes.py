"""Visits as scenes: the whole `Controller` (callbacks, decision steps, audio calls,
the camera->eyes transform) on a fake clock, with a fake node whose audio server
plays each sound for its duration on that clock. No router, no processes, no
threads: every scene runs in milliseconds and the same way every time.
test_controller_scenarios.py keeps one visit end to end through real processes."""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Callable
from typing import Any

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.controller.service import Controller
from buddybot.controller.settings import ControllerSettings

from .conftest import FAST_CONFIG
from .fakes import Clock, FakeNode
from .test_controller_state import news

X = m.ExpressionAction
STEP_S = 0.05
FACE_EVERY_S = 0.1


class CallFailed(Exception):
    """What a failing audio call raises here (a timeout or a broken session)."""


class Scene:
    """The controller of FAST_CONFIG (with `overrides`), a radar/camera stimulus and
    an audio server like the real one: a call is answered at once, the status goes
    ACCEPTED -> PLAYING -> SUCCEEDED (or CANCELED), `device_free` is false while a
    sound plays. `refuse`: sounds the server refuses; `fail`: sounds whose call fails.
    `log` reads like FakeAudio's: "play:greeting", "cancel:greeting", "end:greeting"."""

    def __init__(self, durations: dict[str, float] | None = None,
                 refuse: frozenset[str] = frozenset(), fail: frozenset[str] = frozenset(),
                 **overrides: Any) -> None:
        params = tomllib.loads(FAST_CONFIG)["controller"] | overrides
        self.clock = Clock()
        self.node = FakeNode(self._call)
        self.controller = Controller(self.node, msgspec.convert(params, ControllerSettings),
                                     clock=self.clock)  # type: ignore[arg-type]
        self.durations = durations or {}
        self.refuse, self.fail = refuse, fail
        self.log: list[str] = []
        self.overlaps = 0
        self.sounds: list[str] = []
        self.playing: dict[str, tuple[str, float]] = {}  # goal id -> (sound, ends at)
        self.watching = False
        self.point = m.Point(x=1.0, y=0.3, z=0.0)
        self._next_face = 0.0
        self._next_tick = 0.0
        self._device_free(True)  # latched by the audio server before the controller came
        self.until(lambda: self.expressions() == [X.EYE_SLEEP], "initial EYE_SLEEP")

    # -- what the test sees --

    def expressions(self) -> list[X]:
        return [msg.action for msg in self.node.publishers["eyes/expression"].sent]

    def controls(self) -> list[m.EyeControl]:
        return list(self.node.publishers["eyes/control"].sent)

    def states(self) -> list[m.ControllerState]:
        return list(self.node.publishers["controller/state"].sent)

    # -- the stimulus --

    def presence(self, in_range: bool) -> None:
        state = m.PresenceState.IN_RANGE if in_range else m.PresenceState.OUT_OF_RANGE
        self.controller._on_presence(m.PresenceDetection(
            stamp_ns=m.now_ns(), target_state=m.PresenceTarget.STANDING,
            presence_state=state, distance_m=1.2), "radar/presence")
        self._settle()

    def face(self) -> int:
        stamp = m.now_ns()
        self.controller._on_face(m.FacePosition(stamp_ns=stamp, frame_id="front",
                                                point=self.point, confidence=0.9), "face")
        self._settle()
        return stamp

    def watch(self, on: bool) -> None:
        """A face every FACE_EVERY_S from now on (a camera that sees someone), or none."""
        self.watching = on
        self._next_face = self.clock.t

    # -- time --

    def run(self, seconds: float) -> None:
        end = self.clock.t + seconds
        while self.clock.t < end - 1e-9:
            self._step()

    def until(self, done: Callable[[], object], what: str, limit_s: float = 10.0) -> None:
        """Advance the fake clock until `done()`; fails after `limit_s` of fake time."""
        end = self.clock.t + limit_s
        while not done():
            if self.clock.t > end:
                raise AssertionError(f"{what} not within {limit_s} s: {self.log}, "
                                     f"{self.expressions()}")
            self._step()

    def _step(self) -> None:
        self.clock.t = round(self.clock.t + STEP_S, 6)
        for goal_id, (sound, ends) in list(self.playing.items()):
            if self.clock.t >= ends:
                self._end(goal_id, sound, "SUCCEEDED")
        if self.watching and self.clock.t >= self._next_face - 1e-9:
            self._next_face = self.clock.t + FACE_EVERY_S
            self.face()
        self._settle()

    def _settle(self) -> None:
        """What the sound and decision threads would do next: every queued audio call,
        then a decision step on the inbox, until neither has anything left."""
        c = self.controller
        while True:
            while not c._sounds.empty():
                cmd = c._sounds.get_nowait()
                assert cmd is not None
                c.call_audio(cmd)
            events = list(c._inbox)
            c._inbox.clear()
            self._next_tick = c.decision_step(events, self._next_tick)
            if not c._inbox and c._sounds.empty():
                return

    # -- the audio server --

    def _status(self, goal_id: str, state: str) -> None:
        self.controller._on_status(m.PlaySoundStatus(goal_id=goal_id, state=state,  # type: ignore[arg-type]
                                                     stamp_ns=m.now_ns()), "status")

    def _device_free(self, free: bool) -> None:
        self.controller._on_device_free(m.Bool(stamp_ns=m.now_ns(), data=free), "free")

    def _end(self, goal_id: str, sound: str, state: str) -> None:
        del self.playing[goal_id]
        self.log.append(f"{'canceled' if state == 'CANCELED' else 'end'}:{sound}")
        self._status(goal_id, state)
        self._device_free(True)

    def _call(self, service: Any, request: Any, _timeout: float) -> Any:
        if service is keys.PLAY_SOUND:
            return self._play(request)
        assert service is keys.PLAY_SOUND_CANCEL
        entry = self.playing.get(request.goal_id)
        self.log.append(f"cancel:{entry[0] if entry else '?'}")
        if entry is None:
            return m.TriggerReply(success=False, message="no such goal")
        self._end(request.goal_id, entry[0], "CANCELED")
        return m.TriggerReply(success=True)

    def _play(self, request: m.PlaySound) -> m.PlaySoundReply:
        sound = request.sound
        if sound in self.fail:
            self.log.append(f"failed:{sound}")
            raise CallFailed("no answer")
        if sound in self.refuse:
            self.log.append(f"refused:{sound}")
            return m.PlaySoundReply(goal_id="", accepted=False, message="refused by test")
        goal_id = f"g{len(self.sounds) + 1}"
        self.overlaps += bool(self.playing)
        self.playing[goal_id] = (sound, self.clock.t + self.durations.get(sound, 0.5))
        self.sounds.append(sound)
        self.log.append(f"play:{sound}")
        self._status(goal_id, "ACCEPTED")
        self._device_free(False)
        self._status(goal_id, "PLAYING")
        return m.PlaySoundReply(goal_id=goal_id, accepted=True)


def no_repeats(seq: list[X]) -> bool:
    return all(a != b for a, b in itertools.pairwise(seq))


def test_approach_greet_follow_leave_farewell() -> None:
    s = Scene(durations={"greeting": 0.8, "farewell": 0.8})
    s.presence(True)
    assert s.expressions()[-1] == X.EYE_AWAKE
    s.watch(True)
    s.until(lambda: "play:greeting" in s.log, "greeting")
    assert s.expressions()[-1] == X.EYE_GRIN
    s.until(lambda: "end:greeting" in s.log, "greeting ended")
    s.until(lambda: s.expressions()[-1] == X.EYE_AWAKE, "awake after the greeting")

    # Following: a face to the left and up gives +yaw, +pitch, its stamp kept.
    s.watch(False)
    s.point = m.Point(x=1.0, y=0.5, z=0.2)
    stamp = s.face()
    msg = s.controls()[-1]
    assert msg.stamp_ns == stamp
    # camera 10 cm above the eyes centre (FAST_CONFIG): z = 0.3 in the eyes frame
    assert msg.yaw == pytest.approx(math.atan2(0.5, 1.0))
    assert msg.pitch == pytest.approx(math.atan2(0.3, math.hypot(1.0, 0.5)))
    assert msg.target_distance_cm == pytest.approx(math.sqrt(1.0 + 0.25 + 0.09) * 100)

    s.presence(False)
    s.until(lambda: "play:farewell" in s.log, "farewell")
    s.until(lambda: s.expressions()[-1] == X.EYE_SLEEP, "asleep again")
    assert s.sounds == ["greeting", "farewell"] and s.overlaps == 0
    assert s.expressions() == [X.EYE_SLEEP, X.EYE_AWAKE, X.EYE_GRIN, X.EYE_AWAKE,
                               X.EYE_SLEEPY, X.EYE_SLEEP]


def test_passer_by_is_not_greeted() -> None:
    s = Scene(greet_dwell_s=3.0, absence_hold_s=0.3, sleepy_s=0.3)
    s.presence(True)
    s.watch(True)
    s.run(1.0)
    s.presence(False)  # walks on well within the 3 s dwell
    s.watch(False)
    s.until(lambda: s.expressions()[-1] == X.EYE_SLEEP, "asleep again")
    s.run(5.0)  # and nothing comes later either
    assert s.sounds == [] and s.log == []
    assert s.expressions() == [X.EYE_SLEEP, X.EYE_AWAKE, X.EYE_SLEEPY, X.EYE_SLEEP]


def test_radar_flicker_neither_flaps_the_eyes_nor_regreets() -> None:
    s = Scene(durations={"greeting": 0.3}, greet_dwell_s=0.3, absence_hold_s=2.0,
              sleepy_s=0.3)
    s.presence(True)
    s.watch(True)
    s.until(lambda: "end:greeting" in s.log, "greeting ended")
    s.until(lambda: s.expressions()[-1] == X.EYE_AWAKE, "awake after the greeting")
    for _ in range(8):  # a radar at the edge of its range: 150 ms dropouts
        s.presence(False)
        s.run(0.15)
        s.presence(True)
        s.run(0.15)
    s.presence(False)
    s.watch(False)
    s.until(lambda: "play:farewell" in s.log, "farewell")
    s.until(lambda: s.expressions()[-1] == X.EYE_SLEEP, "asleep again")
    assert s.sounds == ["greeting", "farewell"]
    assert s.expressions() == [X.EYE_SLEEP, X.EYE_AWAKE, X.EYE_GRIN, X.EYE_AWAKE,
                               X.EYE_SLEEPY, X.EYE_SLEEP]


def test_face_occlusion_holds_then_centres_and_looks_around() -> None:
    s = Scene(durations={"greeting": 0.3})
    s.presence(True)
    s.watch(True)
    s.until(lambda: "end:greeting" in s.log, "greeting ended")
    s.until(lambda: s.expressions()[-1] == X.EYE_AWAKE, "awake after the greeting")
    s.watch(False)  # the face is hidden
    hidden = len(s.controls())
    s.until(lambda: len(s.controls()) > hidden, "gaze back to centre")
    centre = s.controls()[-1]
    assert (centre.yaw, centre.pitch) == (0.0, 0.0)
    assert centre.target_distance_cm == pytest.approx(100.0)
    s.until(lambda: s.expressions()[-1] == X.EYE_LOOK_RANDOM, "looking around")
    s.watch(True)  # visible again: same visit, no second greeting
    s.until(lambda: s.expressions()[-1] == X.EYE_AWAKE, "awake on the face")
    s.presence(False)
    s.watch(False)
    s.until(lambda: "play:farewell" in s.log, "farewell")
    assert s.sounds == ["greeting", "farewell"]
    assert no_repeats(s.expressions())


def test_quick_walk_away_cancels_the_greeting_then_says_farewell() -> None:
    s = Scene(durations={"greeting": 30.0, "farewell": 0.5})
    s.presence(True)
    s.watch(True)
    s.until(lambda: "play:greeting" in s.log, "greeting")
    s.presence(False)
    s.watch(False)
    s.until(lambda: "end:farewell" in s.log, "farewell played")
    assert s.log == ["play:greeting", "cancel:greeting", "canceled:greeting",
                     "play:farewell", "end:farewell"]
    assert s.overlaps == 0
    s.until(lambda: s.expressions()[-2:] == [X.EYE_SLEEPY, X.EYE_SLEEP], "asleep again")


@pytest.mark.parametrize(("how", "logged"), [("refuse", "refused:greeting"),
                                             ("fail", "failed:greeting")])
def test_refused_and_failing_audio_do_not_stop_the_controller(how: str, logged: str) -> None:
    s = Scene(**{how: frozenset({"greeting"})})  # type: ignore[arg-type]
    s.presence(True)
    s.watch(True)
    s.until(lambda: logged in s.log, "greeting refused")
    s.presence(False)
    s.watch(False)
    s.until(lambda: s.expressions()[-2:] == [X.EYE_SLEEPY, X.EYE_SLEEP], "asleep again")
    s.run(5.0)
    assert s.sounds == []  # nobody was greeted, so no farewell
    assert s.log == [logged]  # and no retry within the cooldown
    assert s.node.diagnostics.values.get("sound_call_failures", 0) == (how == "fail")
    stamp = s.face()
    assert s.controls()[-1].stamp_ns == stamp  # still following faces


def test_the_state_is_published_at_start_and_then_on_change_only() -> None:
    s = Scene()
    assert s.states()[0].waiting == "recovery"  # the first one, before any input
    s.until(lambda: s.states()[-1].waiting == "nothing", "the state after the recovery")
    assert s.states()[-1].phase == "idle"
    s.presence(True)
    noticed = s.states()[-1]
    assert (noticed.phase, noticed.in_range, noticed.visit, noticed.waiting) == (
        "noticed", True, 1, "face")
    s.face()  # published from the face callback, right after the eye control
    engaged = s.states()[-1]
    assert (engaged.phase, engaged.waiting, engaged.face_visible) == ("engaged", "dwell", True)
    assert 0.0 < engaged.waiting_s <= 0.5  # greet_dwell_s of FAST_CONFIG
    s.run(0.3)  # the dwell counts down: not a change worth a publication
    assert s.states()[-1] == engaged
    assert [(a, b) for a, b in itertools.pairwise(s.states()) if news(a) == news(b)] == []
