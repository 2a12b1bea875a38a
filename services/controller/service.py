"""`buddybot run controller`: the robot's own behaviour, an app on the SDK.

It asks the robot what any app may ask (`bot.people.on_state`,
`bot.on_face`, `bot.speaker`, `bot.leases.on_held`, `bot.params.offer`)
and answers with wishes (`bot.wishes`): the eyes driver's arbiter shows
them while no lease holds those parts. A face is the latency path (camera
-> eyes), so it is decided in its callback under the lock that guards the
`Behaviour`; every other callback only posts an event to the decision
thread, which runs `tick()` and publishes; one sound thread makes the
blocking speaker calls. `controller/state` is published at start and on
change.

Threads, leases and state, and why: docs/controller.md, 'The service in detail'.
"""

from __future__ import annotations

import argparse
import collections
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from typing import assert_never

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.controller.behaviour import (
    Behaviour,
    CancelSound,
    Command,
    Look,
    PlaySound,
    SetExpression,
    State,
)
from buddybot.controller.events import (
    CancelReply,
    Crowd,
    DeviceFree,
    Event,
    GoalReply,
    PeopleChanged,
    RadarGaze,
    SoundStatus,
    Yielded,
    people_changed,
    person_point,
    radar_point,
)
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze, RigidTransform, face_gaze
from buddybot.sdk import Bot, Refused
from buddybot.sdk.faces import Face
from buddybot.sdk.leases import Parts
from buddybot.sdk.persons import PeopleNow, Person
from buddybot.sdk.service import (
    ConfigError,
    RateLimitedLog,
    ServiceContext,
    run_builtin,
    settings_of,
    settings_option,
)
from buddybot.sdk.speaker import GoalStatus

log = logging.getLogger("buddybot.controller")

CROWD_PERIOD_NS = 90_000_000
"""The whole crowd goes to the behaviour at most every ~0.1 s (and at once when who
is there, or who shows them, changed)."""
SoundCommand = PlaySound | CancelSound
"""The commands the sound thread carries out (blocking audio calls)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The option overrides its `[controller]` key (default: settings.py)."""
    settings_option(parser, "--camera", struct=ControllerSettings, field="camera",
                    metavar="NAME")


def settings_from(ctx: ServiceContext) -> ControllerSettings:
    """`[controller]` with the command line on top: what `run` builds the Controller
    (and its Behaviour) from."""
    return settings_of(ctx, ControllerSettings)


def camera_transform(settings: ControllerSettings) -> RigidTransform:
    """The configured camera->eyes transform, or ConfigError naming the problem."""
    if not keys.valid_robot_id(settings.camera):
        raise ConfigError(f"[controller] camera: invalid camera name {settings.camera!r}")
    try:
        return RigidTransform.from_rpy(
            settings.camera_to_eyes.translation_m, settings.camera_to_eyes.rpy_rad)
    except ValueError as exc:
        raise ConfigError(f"[controller.camera_to_eyes]: {exc}") from None


class Controller:
    """The built-in behaviour on one `Bot`: `run(bot, stop_event)` like any app;
    `start(bot)` subscribes and starts the threads, `close()` stops them."""

    def __init__(self, settings: ControllerSettings,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transform = camera_transform(settings)
        self.settings = settings
        self.clock = clock
        self.behaviour = Behaviour(settings, clock())
        self._yielded: Parts = ()
        """What leases hold (from `leases/state`), shown in `controller/state`."""
        self._inbox: collections.deque[Event] = collections.deque(maxlen=1024)
        self._last_people: PeopleChanged | None = None
        """The last presence posted (under `_cond`): the next is posted only if it differs."""
        self._last_radar: RadarGaze | None = None
        """The last radar direction posted (under `_cond`), likewise."""
        self._crowd_who: tuple[tuple[int, str | None], ...] | None = None
        self._crowd_stamp = 0
        """Who the last crowd posted listed (id, seen by) and its stamp (under `_cond`)."""
        self._cond = threading.Condition()
        self._lock = threading.Lock()
        """Guards `behaviour` and the publishers' order: the decision thread and the
        face callback both decide."""
        self._sounds: queue.Queue[SoundCommand | None] = queue.Queue()
        self._warn = RateLimitedLog(log)
        self._stop = threading.Event()
        self._state: tuple[State, Parts] | None = None  # the last one put
        self._threads: list[threading.Thread] = []
        self._last_diag = 0.0
        self._bot: Bot | None = None

    @property
    def bot(self) -> Bot:
        if self._bot is None:
            raise RuntimeError("the controller is not started (start(bot) first)")
        return self._bot

    # -- lifetime --

    def run(self, bot: Bot, stop_event: threading.Event) -> None:
        """The app's entry: offer the live settings, start, wait for the stop, close."""
        bot.params.offer(self.settings, self.apply_settings)
        self.start(bot, stop_event)
        try:
            stop_event.wait()
        finally:
            self.close()

    def apply_settings(self, settings: ControllerSettings) -> None:
        """A live parameter change (`buddybot param set controller ...`): the
        behaviour reads `self.s` on every decision, so the next one uses it.
        Fields read once at start (camera, transform, tick, call timeout,
        recovery) are restart-only in settings.py."""
        with self._lock:
            self.settings = settings
            self.behaviour.s = settings

    def start(self, bot: Bot, stop_event: threading.Event | None = None) -> None:
        """Take `bot`'s outputs, publish the first state, subscribe, start the
        decision and sound threads (they end with `stop_event` or `close()`)."""
        self.attach(bot)
        if stop_event is not None:
            self._stop = stop_event
        with self._lock:
            self._publish_state(self.clock())  # the first one, even before any input
        # The speaker first: after a restart its latched status must come before the
        # recovery that the first (latched) presence starts is over, or the visitor
        # still there would be greeted again; asked first, it is answered first.
        bot.speaker.on_status(self._on_status)
        bot.speaker.on_free(self._on_device_free)
        bot.people.on_state(self._on_people)
        bot.on_face(self._on_face, camera=self.settings.camera)
        bot.leases.on_held(self._on_leases)
        for target, name in ((self._decide, "decide"), (self._sound_worker, "sound")):
            thread = threading.Thread(target=target, name=f"controller:{name}", daemon=True)
            thread.start()
            self._threads.append(thread)

    def attach(self, bot: Bot) -> None:
        """Take `bot`'s wishes, state publisher and diagnostics (tests drive a
        controller attached to a fake bot without starting it)."""
        self._bot = bot
        self._wishes = bot.wishes
        self._state_pub = bot.publisher(keys.CONTROLLER_STATE)

    def close(self) -> None:
        self._stop.set()
        self._sounds.put(None)
        with self._cond:
            self._cond.notify_all()
        for thread in self._threads:
            thread.join(5.0)

    # -- the SDK's callbacks: enqueue only --

    def _post(self, event: Event) -> None:
        """Hand an event to the decision thread (any thread; never blocks)."""
        with self._cond:
            self._inbox.append(event)
            self._cond.notify()

    def _on_people(self, now: PeopleNow) -> None:
        # `people/state` changes as a visitor moves (up to 10 times a second). Presence and
        # the followed person's radar direction are posted on change; the whole
        # crowd (attention, motion) always, the newest replacing one not yet handled.
        with self._cond:
            follow = None if self._last_people is None else self._last_people.person_id
            change = people_changed(now.people, follow)
            point = radar_point(now.people, change.person_id)
            gaze = None
            if point is not None:
                try:
                    gaze = face_gaze(self.transform, point)
                except ValueError:  # cannot happen with a valid message; never NaN gaze
                    gaze = None
            radar = RadarGaze(gaze, now.stamp_ns if gaze is not None else None)
            # The crowd first: a new presence is then decided knowing who it is.
            # Motion and attention need ~10 states/s, not every camera frame.
            who = tuple((p.id, p.seen_by) for p in now.people)
            if who != self._crowd_who or not (
                    0 <= now.stamp_ns - self._crowd_stamp < CROWD_PERIOD_NS):
                self._crowd_who, self._crowd_stamp = who, now.stamp_ns
                for pending in [e for e in self._inbox if isinstance(e, Crowd)]:
                    self._inbox.remove(pending)  # only the newest matters
                self._inbox.append(Crowd(now.people, self._gazes(now.people), now.stamp_ns))
            if change != self._last_people:
                self._last_people = change
                self._inbox.append(change)
            if radar.gaze != (None if self._last_radar is None else self._last_radar.gaze):
                self._last_radar = radar
                self._inbox.append(radar)
            self._cond.notify()

    def _gazes(self, people: tuple[Person, ...]) -> dict[int, Gaze]:
        """Each person with a direction, as a gaze in the eyes frame."""
        out: dict[int, Gaze] = {}
        for person in people:
            point = person_point(person)
            if point is None:
                continue
            try:
                out[person.id] = face_gaze(self.transform, point)
            except ValueError:  # cannot happen with a valid message; never NaN gaze
                continue
        return out

    def _on_device_free(self, free: bool) -> None:
        self._post(DeviceFree(free))

    def _on_status(self, status: GoalStatus) -> None:
        # The age lets a restarted controller tell a fresh latched status from an old one.
        age = (m.now_ns() - status.stamp_ns) / 1e9 if status.stamp_ns > 0 else None
        self._post(SoundStatus(status.goal_id, status.state, age))

    def _on_leases(self, parts: Parts) -> None:
        self._post(Yielded(parts))

    def _on_face(self, face: Face) -> None:
        with self._lock:
            now = self.clock()
            self._handle_face(face, now)
            self._publish_state(now)

    # -- decision thread --

    def _decide(self) -> None:
        stop = self._stop
        next_tick = self.clock() + self.settings.tick_s
        while not stop.is_set():
            with self._cond:
                while not self._inbox and not stop.is_set():
                    left = next_tick - self.clock()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                events = list(self._inbox)
                self._inbox.clear()
            try:
                next_tick = self.decision_step(events, next_tick)
            except Exception as exc:  # a bug must not stop the robot's behaviour
                self.bot.diagnostics.increment("decision_errors")
                self._warn.warning("decide", "decision step failed: %r", exc)

    def decision_step(self, events: list[Event], next_tick: float) -> float:
        """Hand `events` to the behaviour, tick it when `next_tick` has come, publish
        what changed; returns when the next tick is due. The decision thread runs
        this, and pure tests drive it with a fake clock and bot."""
        with self._lock:
            self._handle(events)
            now = self.clock()
            if now >= next_tick:
                next_tick = now + self.settings.tick_s
                self._execute(self.behaviour.tick(now))
                self._publish_diagnostics(now)
            self._publish_state(now)
        return next_tick

    def _handle(self, events: list[Event]) -> None:
        b = self.behaviour
        for event in events:
            now = self.clock()
            # Exhaustive: an Event member without a case fails type checking at
            # assert_never, and at run time it raises instead of being dropped.
            match event:
                case PeopleChanged(in_range=in_range, person_id=person_id, name=name,
                                   held=held, face=face):
                    commands = b.presence(now, in_range, person_id, name, held, face)
                case RadarGaze(gaze=gaze, stamp_ns=stamp_ns):
                    commands = b.radar(now, gaze, stamp_ns)
                case Crowd(people=people, gazes=gazes, stamp_ns=stamp_ns):
                    commands = b.people(now, people, gazes, stamp_ns)
                case DeviceFree(free=free):
                    commands = b.device_free(now, free)
                case SoundStatus(goal_id=goal_id, state=state, age_s=age_s):
                    commands = b.sound_status(now, goal_id, state, age_s)
                case GoalReply(request=request, accepted=accepted, goal_id=goal_id):
                    commands = b.sound_reply(now, request, accepted, goal_id)
                case CancelReply(goal_id=goal_id, success=success):
                    commands = b.cancel_reply(now, goal_id, success)
                case Yielded(resources=resources):
                    audio_changed = ("audio" in resources) != ("audio" in self._yielded)
                    self._yielded = resources
                    commands = b.audio_held(now, "audio" in resources) if audio_changed else []
                case _:
                    assert_never(event)
            self._execute(commands)

    def _handle_face(self, face: Face, arrived: float) -> None:
        try:
            gaze = face_gaze(self.transform, (face.x_m, face.y_m, face.z_m))
        except ValueError as exc:
            self.bot.diagnostics.increment("bad_faces")
            self._warn.warning("face", "ignored face: %s", exc)
            return
        self._execute(self.behaviour.face(arrived, gaze, face.stamp_ns))

    def _execute(self, commands: list[Command]) -> None:
        """Carry out the behaviour's commands. Exhaustive: a `Command` member without a
        case fails type checking at `assert_never`, and at run time it raises instead
        of being taken for a sound."""
        for cmd in commands:
            match cmd:
                case Look():
                    self._look(cmd)
                case SetExpression(action=action):
                    log.info("expression -> %s", action.name)
                    self._wishes.express(action)
                case PlaySound() | CancelSound():
                    self._sounds.put(cmd)
                case _:
                    assert_never(cmd)

    def _look(self, cmd: Look) -> None:
        """The gaze wish: at the face (clamped to the eyes' range), or ahead at
        `centre_distance_cm` when there is none."""
        if cmd.gaze is None:
            self._wishes.look_at(0.0, 0.0, self.settings.centre_distance_cm / 100,
                                 stamp_ns=cmd.stamp_ns)
            return
        g = cmd.gaze
        self._wishes.look_at(_clamp(g.yaw, math.pi), _clamp(g.pitch, math.pi / 2),
                             g.distance_cm / 100, stamp_ns=cmd.stamp_ns)

    def _publish_state(self, now: float) -> None:
        """Put `controller/state` if it changed (beyond `waiting_s`); under the lock."""
        current = (self.behaviour.state(now), self._yielded)
        if current == self._state:
            return
        self._state = current
        self._state_pub.put(state_message(current[0], now, m.now_ns(), list(current[1])))

    def _publish_diagnostics(self, now: float) -> None:
        if now - self._last_diag < 1.0:
            return
        self._last_diag = now
        snap = self.behaviour.snapshot(now)
        values = self.bot.diagnostics.values
        values["phase"] = snap.phase.value
        values["expression"] = snap.expression.name if snap.expression is not None else "-"
        values["greeted"] = snap.greeted
        values["sound"] = snap.sound or "-"
        values["recovering"] = snap.recovering
        values["farewell_pending"] = snap.farewell_pending
        values.update(snap.counters)

    # -- sound thread --

    def _sound_worker(self) -> None:
        while True:
            cmd = self._sounds.get()
            if cmd is None or self._stop.is_set():
                return
            self.call_audio(cmd)

    def call_audio(self, cmd: SoundCommand) -> None:
        """Make one blocking speaker call and post its answer to the inbox; a failed
        call is answered too (refused, not successful), so the behaviour never waits
        for a reply that cannot come."""
        timeout = self.settings.call_timeout_s
        speaker = self.bot.speaker
        match cmd:
            case PlaySound(sound=sound, request=request):
                log.info("play_sound %r", sound)
                try:
                    handle = speaker.play(sound, timeout=timeout)
                    self._post(GoalReply(request, True, handle.goal_id))
                except Refused as exc:
                    log.warning("play_sound %r refused: %s", sound, exc.reason)
                    self._post(GoalReply(request, False, ""))
                except Exception as exc:  # NoService, or the bus failing: always answer
                    self.bot.diagnostics.increment("sound_call_failures")
                    log.warning("play_sound %r failed: %s", sound, exc)
                    self._post(GoalReply(request, False, ""))
            case CancelSound(goal_id=goal_id):
                log.info("cancel goal %s", goal_id)
                try:
                    self._post(CancelReply(goal_id, speaker.cancel(goal_id, timeout)))
                except Exception as exc:
                    log.warning("cancel of %s failed: %s", goal_id, exc)
                    self._post(CancelReply(goal_id, False))
            case _:
                assert_never(cmd)


def state_message(state: State, now: float, now_ns: int,
                  yielded: list[m.Resource] | None = None) -> m.ControllerState:
    """The behaviour's state as the message: its times (on the clock of `now`)
    become wall-clock ns, taking `now` to be `now_ns`; `yielded`: what leases hold."""
    def wall(at: float | None) -> int | None:
        return None if at is None else max(0, now_ns - round((now - at) * 1e9))

    return m.ControllerState(
        stamp_ns=now_ns, phase=state.phase.value, expression=state.expression,
        in_range=state.in_range, face_visible=state.face_visible, visit=state.visit,
        person_id=state.person_id,
        greeted=state.greeted, sound=None if state.sound is None else state.sound.value,
        farewell_pending=state.farewell_pending, waiting=state.waiting,
        waiting_s=state.waiting_s,
        last_greeting_ns=wall(state.last_greeting_at),
        last_farewell_ns=wall(state.last_farewell_at), yielded=list(yielded or []),
    )


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    return run_builtin(ctx, Controller(settings))  # a bad config is refused before connecting
