"""Property-based (hypothesis stateful) tests of the behaviour against a model world.

The world is a radar, a camera, an audio action server (replies, status,
device_free, cancel, possibly refusing) and another program that may
occupy the speaker, all driven in arbitrary order and timing. After
every step these invariants are checked on what the controller
commanded:

* never two greetings within the cooldown (also across controller restarts);
* never a farewell without a greeting since the last farewell; across a
  restart, in the restated form of `farewell_only_after_a_greeting`;
* never a sound started while another one plays (ours or someone else's);
* never the same expression twice in a row (within one controller process).

The person in range may also walk (toward, away, fast or slow, with a
second person standing by): the farewell as they walk away and the
greeting held back while they pass must keep every invariant above.
"""

from __future__ import annotations

from dataclasses import dataclass

import msgspec
from hypothesis import event, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from buddybot.contract.messages import TERMINAL_GOAL_STATES, ExpressionAction
from buddybot.controller.behaviour import (
    Behaviour,
    CancelSound,
    Command,
    Look,
    PlaySound,
    SetExpression,
)
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze
from buddybot.sdk.persons import Person
from tests.properties import examples

COOLDOWN = 4.0
FACE_TIMEOUT_S = 0.3
"""The world's people service: a face older than this is not shown."""
SETTINGS = msgspec.convert(
    {
        "farewell_delay_s": 0.5, "gaze_hold_s": 0.5,
        "look_around_after_s": 1.0, "greet_dwell_s": 0.5, "regreet_cooldown_s": COOLDOWN,
        "sleepy_s": 1.0, "farewell_max_delay_s": 2.0, "sound_timeout_s": 6.0, "recover_s": 0.3,
    },
    ControllerSettings,
)


@dataclass
class Playing:
    goal_id: str
    sound: str
    since: float


class World(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.t = 0.0
        self.b = Behaviour(SETTINGS, self.t)
        self.life = 0
        self.restarted = False
        self.dead = False  # between a controller's death and its restart
        self.in_range = False
        self.distance = 1.5
        self.last_face: float | None = None
        self.face_shown = False  # what the world's people service says of the face
        self.playing: Playing | None = None
        self.other_busy = False
        self.device_free = True
        self.pending: list[tuple[int, int, str]] = []  # (life, request, sound)
        self.cancels: list[tuple[int, str]] = []
        self.next_goal = 0
        self.latched_status: tuple[str, str, float] | None = None
        # what was commanded
        self.greetings: list[float] = []  # accepted greetings (they really played)
        self.issued: list[tuple[float, str]] = []
        # greetings, farewells and restarts in order, for the farewell invariant
        self.story: list[tuple[float, str]] = []
        self.expressions: list[ExpressionAction] = []
        self.violations: list[str] = []

    # -- applying the controller's commands --

    def apply(self, cmds: list[Command]) -> None:
        for cmd in cmds:
            if isinstance(cmd, SetExpression):
                if self.expressions and self.expressions[-1] == cmd.action:
                    self.violations.append(f"expression {cmd.action.name} repeated")
                self.expressions.append(cmd.action)
            elif isinstance(cmd, PlaySound):
                busy = self.playing is not None or self.other_busy or any(
                    life == self.life for life, _, _ in self.pending)
                if busy:
                    self.violations.append(f"{cmd.sound} started while a sound plays")
                self.issued.append((self.t, cmd.sound))
                self.story.append((self.t, cmd.sound))
                self.pending.append((self.life, cmd.request, cmd.sound))
            elif isinstance(cmd, CancelSound):
                self.cancels.append((self.life, cmd.goal_id))
            else:
                assert isinstance(cmd, Look)

    def publish_status(self, goal_id: str, state: str) -> None:
        self.latched_status = (goal_id, state, self.t)
        if not self.dead:
            self.apply(self.b.sound_status(self.t, goal_id, state))

    def update_device(self) -> None:
        free = self.playing is None and not self.other_busy
        if free != self.device_free:
            self.device_free = free
            if not self.dead:
                self.apply(self.b.device_free(self.t, free))

    # -- rules: time and senses --

    @rule(dt=st.sampled_from([0.05, 0.1, 0.3, 0.6, 1.5, 5.0]), watching=st.booleans(),
          server=st.booleans(), yaw=st.floats(-1.0, 1.0))
    def advance(self, dt: float, watching: bool, server: bool, yaw: float) -> None:
        """Time passes in 50 ms ticks. `watching`: a face in view at 10 frames/s;
        `server`: the audio server answers goals at once and sounds last 1 s."""
        end = self.t + dt
        n = 0
        while self.t < end:
            self.t = min(end, self.t + 0.05)
            n += 1
            if watching and n % 2 == 0:
                self.see_face(yaw)
            self.people_face()
            if server:
                if self.pending and self.playing is None:
                    self.reply(accept=True, status_first=n % 3 == 0)
                elif self.cancels:
                    self.cancel()
                elif self.playing is not None and self.t - self.playing.since >= 1.0:
                    self.finish("SUCCEEDED")
            self.apply(self.b.tick(self.t))

    @rule(stay=st.sampled_from([0.3, 1.0, 3.0]), away=st.sampled_from([0.3, 1.0, 3.0, 8.0]),
          server=st.booleans())
    def visit(self, stay: float, away: float, server: bool) -> None:
        """A whole visit in one step (makes greetings and farewells common)."""
        self.presence(True)
        self.advance(stay, watching=True, server=server, yaw=0.2)
        self.presence(False)
        self.advance(away, watching=False, server=server, yaw=0.0)

    @rule(in_range=st.booleans())
    def presence(self, in_range: bool) -> None:
        self.in_range = in_range
        self.apply(self.b.presence(self.t, in_range, 1 if in_range else None,
                                   face=self.face_shown))

    def see_face(self, yaw: float) -> None:
        """A face reaches the controller, then the people service's state saying so."""
        self.last_face = self.t
        if not self.dead:
            self.apply(self.b.face(self.t, Gaze(yaw, 0.0, 100.0), 1))
        self.people_face()

    def people_face(self) -> None:
        """The people service's word on the face, when it changes."""
        shown = self.last_face is not None and self.t - self.last_face <= FACE_TIMEOUT_S
        if shown != self.face_shown:
            self.face_shown = shown
            if not self.dead:
                self.apply(self.b.presence(self.t, self.in_range,
                                           1 if self.in_range else None, face=shown))

    @rule(speed=st.sampled_from([-1.5, -0.5, 0.0, 0.5, 1.2]),
          seconds=st.sampled_from([0.3, 1.0, 2.0]), second=st.booleans(),
          bearing=st.booleans())
    def walk(self, speed: float, seconds: float, second: bool, bearing: bool) -> None:
        """The person in range moves radially at `speed` (m/s, + away), a people
        state every 50 ms; `second`: someone else stands near; `bearing`: an angle
        radar gives their direction."""
        if self.dead or not self.in_range:
            return
        end = self.t + seconds
        while self.t < end:
            self.t = min(end, self.t + 0.05)
            self.distance = min(8.0, max(0.3, self.distance + speed * 0.05))
            people = [Person(id=1, zone="PERSONAL", engagement="ENGAGED",
                             distance_m=self.distance,
                             seen_by="BOTH" if self.face_shown else "RADAR",
                             bearing_rad=0.1 if bearing else None)]
            if second:
                people.append(Person(id=2, zone="SOCIAL", engagement="NONE", distance_m=2.0,
                                     seen_by="RADAR", bearing_rad=-0.4))
            gazes = {p.id: Gaze(p.bearing_rad, 0.0, 100.0) for p in people
                     if p.bearing_rad is not None}
            self.apply(self.b.people(self.t, people, gazes, round(self.t * 1e9)))
            self.people_face()
            self.apply(self.b.tick(self.t))
        if self.b.counters["farewells_early"]:
            event("a farewell as they walked away")

    @rule(yaw=st.floats(-1.0, 1.0))
    def face(self, yaw: float) -> None:
        self.see_face(yaw)

    @rule(busy=st.booleans())
    def other_program(self, busy: bool) -> None:
        self.other_busy = busy
        self.update_device()

    # -- rules: the audio action server --

    @precondition(lambda self: bool(self.pending))
    @rule(accept=st.booleans(), status_first=st.booleans())
    def reply(self, accept: bool, status_first: bool) -> None:
        life, request, sound = self.pending.pop(0)
        if not accept:
            if life == self.life:
                self.apply(self.b.sound_reply(self.t, request, False))
            return
        self.next_goal += 1
        gid = f"g{self.next_goal}"
        if self.playing is not None:
            self.violations.append("audio server asked to play two sounds")
        self.playing = Playing(gid, sound, self.t)
        if sound == "greeting":
            if self.greetings and self.t - self.greetings[-1] < COOLDOWN - 1e-9:
                self.violations.append(f"greetings at {self.greetings[-1]} and {self.t}")
            self.greetings.append(self.t)
        if status_first:
            self.publish_status(gid, "ACCEPTED")
        if life == self.life:
            self.apply(self.b.sound_reply(self.t, request, True, gid))
        if not status_first:
            self.publish_status(gid, "ACCEPTED")
        self.publish_status(gid, "PLAYING")
        self.update_device()

    @precondition(lambda self: self.playing is not None)
    @rule(outcome=st.sampled_from(["SUCCEEDED", "ABORTED"]))
    def finish(self, outcome: str) -> None:
        assert self.playing is not None
        gid, self.playing = self.playing.goal_id, None
        self.publish_status(gid, outcome)
        self.update_device()

    @precondition(lambda self: bool(self.cancels))
    @rule()
    def cancel(self) -> None:
        life, gid = self.cancels.pop(0)
        hit = self.playing is not None and self.playing.goal_id == gid
        if life == self.life:
            self.apply(self.b.cancel_reply(self.t, gid, hit))
        if hit:
            self.playing = None
            self.publish_status(gid, "CANCELED")
            self.update_device()

    # -- rule: the controller process restarts --

    @precondition(lambda self: self.life < 2)
    @rule(dice=st.integers(0, 4), play_inflight=st.booleans())
    def restart(self, dice: int, play_inflight: bool) -> None:
        if dice:
            return  # restarts are rare
        # A goal the dying process sent is served at once or never (the new
        # process then learns of it from the latched status and device_free);
        # the dead process hears nothing of it.
        self.life += 1
        self.dead = True
        while self.pending:
            self.reply(accept=play_inflight and self.playing is None, status_first=False)
        self.cancels.clear()
        self.dead = False
        self.restarted = True
        self.story.append((self.t, "restart owing" if self.restart_may_owe() else "restart"))
        self.b = Behaviour(SETTINGS, self.t)
        # latched values replayed to the new process
        # The expression's latched value died with the old process: the new one
        # publishes the current state again, which may equal the last one.
        self.expressions.clear()
        self.apply(self.b.presence(self.t, self.in_range, face=self.face_shown))
        self.apply(self.b.device_free(self.t, self.device_free))
        if self.latched_status is not None:
            gid, state, stamp = self.latched_status
            self.apply(self.b.sound_status(self.t, gid, state, self.t - stamp))

    def restart_may_owe(self) -> bool:
        """True if a controller starting now may owe a goodbye it did not greet for:
        the visitor is in range and the latched status shows a sound less than a
        cooldown old (or still playing). The status does not say which sound it
        was, so it may have been the farewell of this visitor's previous visit."""
        if not self.in_range or self.latched_status is None:
            return False
        _, state, stamp = self.latched_status
        return state not in TERMINAL_GOAL_STATES or self.t - stamp < COOLDOWN

    # -- invariants --

    def teardown(self) -> None:
        event(f"greetings: {min(len(self.greetings), 3)}")
        event(f"farewells: {min(sum(1 for _, s in self.issued if s == 'farewell'), 2)}")
        event(f"restarted: {self.restarted}")

    @invariant()
    def no_violation(self) -> None:
        assert not self.violations, self.violations

    @invariant()
    def farewell_only_after_a_greeting(self) -> None:
        """Every farewell follows a greeting issued since the previous farewell.

        Across restarts too: a new process owes nothing for the old one's
        greetings (that memory died), so after a restart a farewell needs a
        greeting by the new process, with one exception, `restart_may_owe`: the
        visitor was in range at the restart and a sound had played less than a
        cooldown before, which the new process takes for this visit's greeting.
        Only "in range at the restart" may owe: someone arriving during the
        recovery window after a farewell must not get a second farewell.
        """
        owed = False
        greeted_ever = False
        for t, what in self.story:
            if what == "greeting":
                owed = greeted_ever = True
            elif what == "farewell":
                assert owed, f"farewell at {t} without a greeting owed: {self.story}"
                assert greeted_ever, f"farewell at {t} before any greeting: {self.story}"
                owed = False
            else:
                owed = what == "restart owing"


World.TestCase.settings = settings(max_examples=examples(400), stateful_step_count=60)
TestControllerProperties = World.TestCase
