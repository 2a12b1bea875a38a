"""The controller's social behaviour as a pure state machine: events in, commands out.

Nothing here knows Zenoh or threads. Every method takes the current time
`now` (seconds on any monotonic clock; tests pass a fake one) and returns
the commands to carry out: `SetExpression`, `Look`, `PlaySound`,
`CancelSound`. The service feeds it presence (from the people service:
a person shown, held or gone, and their person id), faces, audio status,
device-free flags and service replies, and calls `tick()` periodically so
timers fire. `state(now)` reports what the machine believes and what
holds back the next sound; it changes nothing.

Phases, visits, greeting, farewell, gaze, look before see and the
recovery after a restart: docs/controller.md, 'The state machine in detail'.
"""

from __future__ import annotations

import enum
import math
import random
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from buddybot.contract.messages import (
    TERMINAL_GOAL_STATES,
    ExpressionAction,
    Waiting,
    spoken_text,
)
from buddybot.controller.attention import Attention, Focus
from buddybot.controller.kinematics import Kinematics, Moving, Person, direction
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze

# --- commands ------------------------------------------------------------------------


@dataclass(frozen=True)
class SetExpression:
    """Publish `eyes/expression` (latched)."""

    action: ExpressionAction


@dataclass(frozen=True)
class Look:
    """Publish `eyes/control`; `gaze` None = back to centre. `stamp_ns` of the face."""

    gaze: Gaze | None
    stamp_ns: int | None = None


@dataclass(frozen=True)
class PlaySound:
    """Send an `audio/play_sound` goal; answer with `sound_reply(request, ...)`."""

    sound: str
    request: int


@dataclass(frozen=True)
class CancelSound:
    """Cancel a goal via `audio/play_sound/cancel`; answer with `cancel_reply`."""

    goal_id: str


Command = SetExpression | Look | PlaySound | CancelSound


class Phase(enum.Enum):
    IDLE = "idle"
    NOTICED = "noticed"
    ENGAGED = "engaged"
    LEAVING = "leaving"
    ALONE = "alone"
    DROWSY = "drowsy"


class SoundKind(enum.Enum):
    GREETING = "greeting"
    FAREWELL = "farewell"
    UNKNOWN = "unknown"  # found playing after a restart


@dataclass
class _Goal:
    kind: SoundKind
    since: float
    request: int | None = None
    goal_id: str | None = None
    cancel_sent: bool = False


@dataclass
class _Visit:
    greeted: bool = False
    farewell_done: bool = False


@dataclass
class Snapshot:
    """What the machine believes, for diagnostics and tests."""

    phase: Phase
    expression: ExpressionAction | None
    greeted: bool
    sound: str | None
    farewell_pending: bool
    recovering: bool
    counters: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class State:
    """What `controller/state` reports, on the behaviour's clock (`Behaviour.state`).

    Two states compare equal when only `waiting_s` differs: it counts down all
    the time, so a change of it alone is no news worth a publication.
    """

    phase: Phase
    expression: ExpressionAction | None
    in_range: bool
    face_visible: bool
    visit: int
    """Visits since start (a return within `regreet_cooldown_s` is the same visit)."""
    person_id: int | None
    """The people service's id of the person this visit is about: the one the radar
    showed last (see `Behaviour.presence`); None while IDLE."""
    greeted: bool
    sound: SoundKind | None
    """Our sound playing now (or waiting for the player's reply), if any."""
    farewell_pending: bool
    waiting: Waiting
    """What holds back the next sound (`messages.ControllerState` lists the reasons)."""
    waiting_s: float = field(default=0.0, compare=False)
    """Time left for `dwell` and `cooldown`, else 0."""
    last_greeting_at: float | None = None
    """When the last greeting started (the player accepted it), clock of `now`."""
    last_farewell_at: float | None = None


_MAX_SOUND = 256
"""The longest `PlaySound.sound`."""


def greeting_for(settings: ControllerSettings, name: str | None) -> str:
    """The greeting's sound: the person's own (`greetings`), else `greeting_named`
    with their name, else `greeting_sound` (also when the named text could not be
    spoken: a name that makes the `say:` text invalid must not cost the greeting)."""
    if name is None:
        return settings.greeting_sound
    own = settings.greetings.get(name)
    if own is not None:
        return own
    if not settings.greeting_named:
        return settings.greeting_sound
    sound = settings.greeting_named.replace("{name}", name)
    try:
        spoken_text(sound)
    except ValueError:
        return settings.greeting_sound
    return sound if len(sound) <= _MAX_SOUND else settings.greeting_sound


def _aside(gaze: Gaze, offset: tuple[float, float]) -> Gaze:
    """`gaze` turned by a gaze aversion's (yaw, pitch) offset."""
    if offset == (0.0, 0.0):
        return gaze
    return Gaze(gaze.yaw + offset[0], gaze.pitch + offset[1], gaze.distance_cm)


RUSH_CLOSER_M = 0.4
"""Rushing in also means this much nearer within the motion window (noise never is)."""


# --- the machine -----------------------------------------------------------------------


class Behaviour:
    """The interaction controller's decisions; single-threaded, clock injected."""

    def __init__(self, settings: ControllerSettings, now: float,
                 rng: random.Random | None = None) -> None:
        self.s = settings
        self._recover_until: float | None = now + settings.recover_s
        # inputs
        self._in_range: bool | None = None
        self._held = False
        """The people service still has the person (shown by a sensor or held)."""
        self._person_id: int | None = None
        self._person_name: str | None = None
        """The name the people service gives the visit's person now, if any."""
        self._gone_since: float | None = None
        """When the people service last stopped having anyone present."""
        self._device_free: bool | None = None
        self._yielded = False  # a lease holds the speaker: no sound of ours starts
        self._last_face: float | None = None
        """When a face was last looked at (the gaze's own hold)."""
        self._face_shown = False
        """The people service shows the followed person's face (`seen_by` CAMERA or BOTH)."""
        self._face_since: float | None = None
        self._radar_gaze: Gaze | None = None
        """The followed person's direction from an angle radar; None: not tracked."""
        self._radar_stamp: int | None = None
        self._radar_looked: Gaze | None = None
        """The radar direction last sent as a `Look` (None: the face or centre since)."""
        self._last_look: float | None = None
        """When a face or radar direction was last looked at (the centring hold)."""
        self._crowd: tuple[Person, ...] = ()
        """Everyone the people service lists now (`people`), for attention and motion."""
        self._gazes: Mapping[int, Gaze] = {}
        """Where each of them is, as a gaze (the service transforms their positions)."""
        self._crowd_stamp: int | None = None
        self._kinematics = Kinematics()
        self._moving: dict[int, Moving] = {}
        self._attention = Attention(rng if rng is not None else random.Random())
        self._focus = Focus(None, "main")
        self._face_gaze: tuple[Gaze, int | None] | None = None
        """The last face's gaze and stamp (aversions re-aim at it between faces)."""
        self._aimed: tuple[int | None, Gaze] | None = None
        """(person, gaze) last sent for a glance or an aversion."""
        self._alert_until = -math.inf
        """EYE_ALERT until then (someone noticed nowhere to look at, or rushing in)."""
        self._alerted_visit_at: float | None = None
        """The notice (`_noticed_at`) whose alert was given: once per arrival."""
        self._still_since: float | None = -math.inf
        """Since when the visit's person has not been walking (None: walking now;
        -inf: never seen walking)."""
        # derived state
        self._present = False
        self._noticed_at = now
        self._departed_at: float | None = None
        self._visit = _Visit()
        self._visits = 0  # visits since start
        self._expression: ExpressionAction | None = None
        self._gaze_centred = True
        # sounds
        self._goal: _Goal | None = None
        self._last_greet: float | None = None
        self._farewell_since: float | None = None
        self._greeting_started: float | None = None  # accepted by the player (for reports)
        self._farewell_started: float | None = None
        self._next_request = 1
        self._orphan_status: dict[str, str] = {}
        self._recovered_sound_at: float | None = None
        self._in_range_at_start: bool | None = None  # the latched presence replayed to us
        self.counters: dict[str, int] = {
            "greetings": 0, "farewells": 0, "cancels": 0, "farewells_dropped": 0,
            "sounds_lost": 0, "sounds_refused": 0,
            "farewells_early": 0,
        }

    # -- queries --

    @property
    def recovering(self) -> bool:
        return self._recover_until is not None

    def phase(self, now: float) -> Phase:
        if self._present:
            if self._in_range:
                return Phase.ENGAGED if self._face_visible(now) else Phase.NOTICED
            return Phase.LEAVING
        return self._after_departure(now)

    def snapshot(self, now: float) -> Snapshot:
        return Snapshot(
            phase=self.phase(now), expression=self._expression, greeted=self._visit.greeted,
            sound=None if self._goal is None else self._goal.kind.value,
            farewell_pending=self._farewell_since is not None,
            recovering=self.recovering, counters=dict(self.counters),
        )

    def state(self, now: float) -> State:
        """Everything `controller/state` says, including why no sound plays now."""
        waiting, left = self._waiting(now)
        return State(
            phase=self.phase(now), expression=self._expression, in_range=bool(self._in_range),
            face_visible=self._face_visible(now), visit=self._visits,
            person_id=None if self.phase(now) is Phase.IDLE else self._person_id,
            greeted=self._visit.greeted, sound=None if self._goal is None else self._goal.kind,
            farewell_pending=self._farewell_since is not None, waiting=waiting,
            waiting_s=left, last_greeting_at=self._greeting_started,
            last_farewell_at=self._farewell_started,
        )

    def _waiting(self, now: float) -> tuple[Waiting, float]:
        """What holds back the next sound, and the time left when that is known.

        The same conditions as `_farewell` and `_greeting`, in their order: an owed
        farewell waits only for the sound device; with nobody here no sound is due;
        otherwise the greeting's checks, first that fails named.
        """
        if self.recovering:
            return "recovery", 0.0
        busy: Waiting | None = ("sound_busy" if self._goal is not None else
                                "device_busy" if self._device_free is False else
                                "yielded" if self._yielded else None)
        if self._farewell_since is not None:
            return busy or "nothing", 0.0
        if not self._present:
            return "nothing", 0.0
        if self._visit.greeted:
            return "greeted", 0.0
        if busy is not None:
            return busy, 0.0
        if not self._in_range:
            return "nothing", 0.0  # leaving: no greeting for someone going
        if not self._face_visible(now):
            return "face", 0.0
        face_since = self._face_since if self._face_since is not None else now
        still_since = now if self._still_since is None else self._still_since
        dwell_left = self.s.greet_dwell_s - (now - max(self._noticed_at, face_since,
                                                        still_since))
        if dwell_left > 0:
            return "dwell", dwell_left
        if self._last_greet is not None:
            cooldown_left = self.s.regreet_cooldown_s - (now - self._last_greet)
            if cooldown_left > 0:
                return "cooldown", cooldown_left
        return "nothing", 0.0

    def sound_busy(self) -> bool:
        """True while a sound of ours is unfinished, the player says it is busy, or
        a lease holds the speaker."""
        return self._goal is not None or self._device_free is False or self._yielded

    # -- events --

    def presence(self, now: float, in_range: bool, person_id: int | None = None,
                 name: str | None = None, held: bool = False,
                 face: bool = False) -> list[Command]:
        """A person a sensor shows now is present (`in_range`), or nobody is shown
        (latched, on change); `held`: someone is still there though nobody is
        shown (the people service holds them: LEAVING, no timer of ours). Gone
        (neither): the departure comes
        `farewell_delay_s` later. `person_id`: the people service's id of the
        person; it names the visit's person until another one is in range (kept
        while they leave and the farewell plays, so a tool sees whom the goodbye
        is for). `name`: who that person is, if the people service knows (the
        greeting uses it). `face`: the people service shows that person's face
        (the one notion of a face being seen: engaged, and the greeting's dwell)."""
        if self._recover_until is not None and self._in_range_at_start is None:
            self._in_range_at_start = in_range  # the first one is the replayed latched value
            # The latched sound status was asked for with this one, and may come just
            # after it on a busy machine: listen `recover_s` more from here.
            self._recover_until = max(self._recover_until, now + self.s.recover_s)
        held = in_range or held
        if held != self._held or self._in_range is None:
            self._gone_since = None if held else now
        self._in_range, self._held = in_range, held
        shown = face and in_range
        if shown and not self._face_shown:
            self._face_since = now
        self._face_shown = shown
        if in_range and person_id is not None:
            if person_id != self._person_id:
                self._still_since = -math.inf  # nothing known yet of how they move
            self._person_id = person_id
            self._person_name = name
        return self._step(now)

    def face(self, now: float, gaze: Gaze, stamp_ns: int | None = None) -> list[Command]:
        """A face (already as a gaze in the eyes frame): look at it at once. Whether
        a face is seen is the people service's to say (`presence(face=...)`);
        this is the gaze's fast path."""
        self._last_face = now
        self._face_gaze = (gaze, stamp_ns)
        out = self._step(now)
        if self._glancing():
            return out  # the eyes are on someone else for a moment
        self._last_look = now
        self._gaze_centred = False
        self._radar_looked = None
        self._aimed = None
        return [Look(_aside(gaze, self._focus.offset), stamp_ns), *out]

    def people(self, now: float, people: Sequence[Person], gazes: Mapping[int, Gaze],
               stamp_ns: int | None = None) -> list[Command]:
        """Everyone the people service lists (each `people/state`), with where each is
        as a gaze: whom to attend to, and how the visit's person moves (passing by,
        walking away)."""
        self._crowd, self._gazes, self._crowd_stamp = tuple(people), gazes, stamp_ns
        # Speeds on the people service's clock: states that queued up on a busy
        # machine arrive bunched, which on our clock would read as leaps.
        at = stamp_ns / 1e9 if stamp_ns is not None else now
        self._moving = self._kinematics.update(at, people)
        moving = self._moving.get(self._person_id) if self._person_id is not None else None
        if moving is not None and moving.speed_mps >= self.s.linger_speed_mps:
            self._still_since = None
        elif self._still_since is None:
            self._still_since = now
        if moving is not None and self._walking_away(moving):
            self._visit.farewell_done = True
            self._farewell_since = now
            self.counters["farewells_early"] += 1
        return self._step(now)

    def radar(self, now: float, gaze: Gaze | None, stamp_ns: int | None = None
              ) -> list[Command]:
        """The followed person's direction from an angle radar (eyes frame), or None
        when no angle radar tracks them: looked at at once while no face is visible."""
        self._radar_gaze, self._radar_stamp = gaze, stamp_ns
        out: list[Command] = []
        self._radar_look(now, out)
        return out + self._step(now)

    def device_free(self, now: float, free: bool) -> list[Command]:
        self._device_free = free
        return self._step(now)

    def audio_held(self, now: float, held: bool) -> list[Command]:
        """A lease holds the speaker (True) or gave it back: while held no greeting
        or farewell of ours starts (a farewell still waits its `farewell_max_delay_s`)."""
        self._yielded = held
        return self._step(now)

    def sound_status(
        self, now: float, goal_id: str, state: str, age_s: float | None = None
    ) -> list[Command]:
        """`audio/play_sound/status`. `age_s`: how old the status is (latched replay)."""
        goal = self._goal
        if goal is not None and goal.goal_id == goal_id:
            if state in TERMINAL_GOAL_STATES:
                self._goal = None
        elif self.recovering and goal is None:
            self._recover_status(now, goal_id, state, age_s)
        else:
            # Possibly the status of a goal whose reply has not arrived yet.
            self._orphan_status[goal_id] = state
            while len(self._orphan_status) > 16:
                self._orphan_status.pop(next(iter(self._orphan_status)))
        return self._step(now)

    def sound_reply(
        self, now: float, request: int, accepted: bool, goal_id: str = ""
    ) -> list[Command]:
        """Reply to a PlaySound (accepted False also for a failed call)."""
        goal = self._goal
        if goal is None or goal.request != request:
            return self._step(now)  # a late reply for a goal already given up
        if not accepted or not goal_id:
            self.counters["sounds_refused"] += 1
            self._goal = None
            if goal.kind is SoundKind.GREETING:
                self._visit.greeted = False  # nobody was greeted: no farewell either
        else:
            goal.goal_id = goal_id
            goal.since = now  # the watchdog counts from the acceptance
            if goal.kind is SoundKind.GREETING:
                self._last_greet = now  # the cooldown counts from when it really started
                self._greeting_started = now
            elif goal.kind is SoundKind.FAREWELL:
                self._farewell_started = now
            if self._orphan_status.pop(goal_id, None) in TERMINAL_GOAL_STATES:
                self._goal = None
        return self._step(now)

    def cancel_reply(self, now: float, goal_id: str, success: bool) -> list[Command]:
        """Reply to a CancelSound; the goal ends when its final status arrives."""
        goal = self._goal
        if not success and goal is not None and goal.goal_id == goal_id:
            goal.cancel_sent = True  # do not retry; the watchdog ends it if need be
        return self._step(now)

    def tick(self, now: float) -> list[Command]:
        return self._step(now)

    # -- internals --

    def _face_visible(self, now: float) -> bool:
        return self._face_shown

    def _glancing(self) -> bool:
        """The eyes are on someone other than the person whose face is followed."""
        focus = self._focus
        if focus.person_id is None or focus.reason == "main":
            return False
        face = next((p.id for p in self._crowd if p.seen_by in ("CAMERA", "BOTH")), None)
        return focus.person_id != face

    def _anticipate(self, now: float) -> None:
        """EYE_ALERT for the visit's person just noticed whom no sensor gives a
        direction (the eyes cannot turn to them, so the face reacts), and for
        one rushing in; a slow approach changes nothing (EYE_AWAKE)."""
        if self.s.alert_s <= 0 or not self._present:
            return
        moving = self._moving.get(self._person_id) if self._person_id is not None else None
        if moving is not None and -moving.radial_mps >= self.s.rush_speed_mps \
                and moving.closer_m >= RUSH_CLOSER_M:
            self._alert_until = now + self.s.alert_s
            return
        person = next((p for p in self._crowd if p.id == self._person_id), None)
        fresh = now - self._noticed_at < 1.0 and self._alerted_visit_at != self._noticed_at
        if person is not None and fresh and direction(person) is None \
                and person.seen_by not in ("CAMERA", "BOTH"):
            self._alerted_visit_at = self._noticed_at
            self._alert_until = now + self.s.alert_s

    def _walking_away(self, moving: Moving) -> bool:
        """The greeted visitor, alone, moves away: their goodbye is due now, not only
        once the people service lets them go (the whole hold later)."""
        if not self._present or not self._visit.greeted or self._visit.farewell_done:
            return False
        shown = [p for p in self._crowd if p.seen_by != "NONE"]
        if len(shown) > 1:
            return False  # someone else stays: the goodbye is for when the room empties
        return (moving.radial_mps >= self.s.leave_speed_mps
                and moving.distance_m - moving.nearest_m >= self.s.leave_distance_m)


    def _after_departure(self, now: float) -> Phase:
        """Nobody present: awake and alone for `alone_s` after the last one left,
        then drowsy for `sleepy_s`, then asleep; the farewell, while owed or
        playing, holds the phase it started in."""
        if self._departed_at is None:
            return Phase.IDLE
        since = now - self._departed_at
        farewell = ((self._goal is not None and self._goal.kind is SoundKind.FAREWELL)
                    or self._farewell_since is not None)
        if self.s.alone_s > 0 and (since < self.s.alone_s or farewell):
            return Phase.ALONE
        if self.s.sleepy_s > 0 and (since < self.s.alone_s + self.s.sleepy_s or farewell):
            return Phase.DROWSY
        return Phase.IDLE

    def _recover_status(self, now: float, goal_id: str, state: str, age_s: float | None) -> None:
        if state not in TERMINAL_GOAL_STATES:
            self._goal = _Goal(SoundKind.UNKNOWN, now, goal_id=goal_id)
            age_s = 0.0 if age_s is None else age_s
        if age_s is not None and age_s < self.s.regreet_cooldown_s:
            self._recovered_sound_at = now - max(0.0, age_s)

    def _finish_recovery(self, now: float) -> None:
        self._recover_until = None
        self._alerted_visit_at = self._noticed_at  # someone there at start is no arrival
        sound_at = self._recovered_sound_at
        if sound_at is not None:
            # A sound less than a cooldown ago: no greeting before the cooldown ends.
            self._last_greet = sound_at
            # Assume it was this visit's greeting (a goodbye is owed) only if the
            # visitor was already there when we started. Someone who arrived during
            # the recovery came after an empty room, so that sound was most likely
            # the farewell of their previous visit: owing another one would say
            # goodbye twice after a single greeting.
            if self._present and self._in_range_at_start:
                self._visit.greeted = True

    def _step(self, now: float) -> list[Command]:
        out: list[Command] = []
        if self._recover_until is not None:
            if now < self._recover_until:
                self._update_presence(now, out)
                return out
            self._update_presence(now, out)
            self._finish_recovery(now)
        else:
            self._update_presence(now, out)
        self._watchdog(now)
        self._farewell(now, out)
        self._greeting(now, out)
        self._anticipate(now)
        main = self._person_id if self._present else None
        self._focus = self._attention.update(self.s, now, self._crowd, main)
        self._gaze(now, out)
        self._express(now, out)
        return out

    def _update_presence(self, now: float, out: list[Command]) -> None:
        if self._in_range and not self._present:
            self._present = True
            self._noticed_at = now
            same_visit = (
                self._departed_at is not None
                and now - self._departed_at < self.s.regreet_cooldown_s
            )
            if not same_visit:
                self._visit = _Visit()
                self._visits += 1
            if self._farewell_since is not None:
                # Back before the goodbye could start: the visit goes on.
                self._farewell_since = None
                self._visit.farewell_done = False
        elif self._present and not self._held:
            since = self._gone_since if self._gone_since is not None else now
            if now - since >= self.s.farewell_delay_s:
                self._present = False
                self._departed_at = now
                if self._visit.greeted and not self._visit.farewell_done:
                    self._visit.farewell_done = True
                    self._farewell_since = now

    def _watchdog(self, now: float) -> None:
        goal = self._goal
        # A goal still waiting for its reply is never dropped: the service always
        # answers (call timeout), and the server may yet start it.
        if goal is not None and goal.request is not None and goal.goal_id is None:
            return
        if goal is not None and now - goal.since > self.s.sound_timeout_s:
            self.counters["sounds_lost"] += 1
            self._goal = None

    def _play(self, now: float, kind: SoundKind, sound: str, out: list[Command]) -> None:
        request = self._next_request
        self._next_request += 1
        self._goal = _Goal(kind, now, request=request)
        out.append(PlaySound(sound, request))

    def _farewell(self, now: float, out: list[Command]) -> None:
        if self._farewell_since is None:
            return
        if now - self._farewell_since > self.s.farewell_max_delay_s:
            self._farewell_since = None
            self.counters["farewells_dropped"] += 1
            return
        goal = self._goal
        if goal is not None:
            if goal.kind is SoundKind.GREETING and goal.goal_id and not goal.cancel_sent:
                goal.cancel_sent = True
                self.counters["cancels"] += 1
                out.append(CancelSound(goal.goal_id))
            return
        if self._device_free is False or self._yielded:
            return
        self._farewell_since = None
        self.counters["farewells"] += 1
        self._play(now, SoundKind.FAREWELL, self.s.farewell_sound, out)

    def _greeting(self, now: float, out: list[Command]) -> None:
        if self._visit.greeted or self.sound_busy() or self._farewell_since is not None:
            return
        if self.phase(now) is not Phase.ENGAGED:
            return
        face_since = self._face_since if self._face_since is not None else now
        if self._still_since is None:
            return  # walking past, or not yet slowed down
        if now - max(self._noticed_at, face_since, self._still_since) < self.s.greet_dwell_s:
            return
        if self._last_greet is not None and now - self._last_greet < self.s.regreet_cooldown_s:
            return
        self._visit.greeted = True
        self._last_greet = now
        self.counters["greetings"] += 1
        self._play(now, SoundKind.GREETING,
                   greeting_for(self.s, self._person_name), out)

    def _radar_look(self, now: float, out: list[Command]) -> bool:
        """Look at the radar direction if it is live, no face is visible and it is
        not the one last sent; True while the radar holds the gaze."""
        gaze = self._radar_gaze
        if gaze is None or self._face_visible(now):
            return False
        if gaze != self._radar_looked:
            self._radar_looked = gaze
            self._last_look = now
            self._gaze_centred = False
            out.append(Look(gaze, self._radar_stamp))
        return True

    def _glance(self, now: float, out: list[Command]) -> bool:
        """Look at the person attention chose if it is not the followed face (a
        newcomer, a shared glance); True while such a glance holds the gaze."""
        pid = self._focus.person_id
        gaze = self._gazes.get(pid) if pid is not None and self._glancing() else None
        if gaze is None:
            return False
        if (pid, gaze) != self._aimed:
            self._aimed = (pid, gaze)
            self._last_look = now
            self._gaze_centred = False
            self._radar_looked = None
            out.append(Look(gaze, self._crowd_stamp))
        return True

    def _gaze(self, now: float, out: list[Command]) -> None:
        if self._glance(now, out):
            return
        self._aimed = None
        if self._radar_look(now, out):
            return
        if self._gaze_centred or self._last_look is None:
            return
        if now - self._last_look >= self.s.gaze_hold_s:
            self._gaze_centred = True
            self._radar_looked = None
            out.append(Look(None))

    def _desired_expression(self, now: float) -> ExpressionAction | None:
        phase = self.phase(now)
        if phase is Phase.IDLE:
            return ExpressionAction.EYE_SLEEP
        if phase is Phase.DROWSY:
            return ExpressionAction.EYE_SLEEPY
        if phase is Phase.ALONE:  # looks around once the goodbye is said
            busy = self._farewell_since is not None or self._goal is not None
            if busy or not self.s.look_around:
                return ExpressionAction.EYE_AWAKE
            return ExpressionAction.EYE_LOOK_RANDOM
        if phase is Phase.LEAVING:
            return None  # keep whatever is shown: flicker must not flap the eyes
        goal = self._goal
        if goal is not None and goal.kind is SoundKind.GREETING and not goal.cancel_sent:
            return ExpressionAction.EYE_GRIN
        if now < self._alert_until:
            return ExpressionAction.EYE_ALERT
        if phase is Phase.ENGAGED or not self.s.look_around or self._radar_gaze is not None:
            return ExpressionAction.EYE_AWAKE
        last_seen = max(self._noticed_at, self._last_face or self._noticed_at)
        if now - last_seen >= self.s.look_around_after_s:
            return ExpressionAction.EYE_LOOK_RANDOM
        return ExpressionAction.EYE_AWAKE

    def _express(self, now: float, out: list[Command]) -> None:
        wanted = self._desired_expression(now)
        if wanted is not None and wanted != self._expression:
            self._expression = wanted
            out.append(SetExpression(wanted))
