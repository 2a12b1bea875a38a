"""`buddybot run controller`: the thin adapter between Zenoh and `behaviour.Behaviour`.

A face is the latency path (camera -> eyes), so it is decided in Zenoh's
callback thread under the lock that guards the `Behaviour`; every other
callback only posts an event to the decision thread, which runs `tick()`
and publishes; one sound thread makes the blocking audio calls. The
behaviour's expression and gaze are wishes (`controller/expression`,
`controller/eye_control`): the eyes driver's arbiter shows them while no
lease holds those parts. `controller/state` is published at start and on change.

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
    DeviceFree,
    Event,
    GoalReply,
    PeopleChanged,
    RadarGaze,
    SoundStatus,
    Yielded,
    people_changed,
    radar_point,
    yielded,
)
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import RigidTransform, face_gaze
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node, RateLimitedLog
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext

log = logging.getLogger("buddybot.controller")

SoundCommand = PlaySound | CancelSound
"""The commands the sound thread carries out (blocking audio calls)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The option overrides its `[controller]` key (default: settings.py)."""
    settings_option(parser, "--camera", struct=ControllerSettings, field="camera",
                    metavar="NAME")


def settings_from(ctx: ServiceContext) -> ControllerSettings:
    """`[controller]` with the command line on top: what `run` builds the Controller
    (and its Behaviour) from."""
    return merge(ctx.config.section(ControllerSettings), ctx.args)


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
    """Wires one Node to one Behaviour; `start()` declares everything, `close()` stops."""

    def __init__(self, node: Node, settings: ControllerSettings,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.transform = camera_transform(settings)
        self.node = node
        self.settings = settings
        self.clock = clock
        self.behaviour = Behaviour(settings, clock())
        self._yielded: tuple[m.Resource, ...] = ()
        """What leases hold (from `leases/state`), shown in `controller/state`."""
        self._inbox: collections.deque[Event] = collections.deque(maxlen=1024)
        self._last_people: PeopleChanged | None = None
        """The last presence posted (under `_cond`): the next is posted only if it differs."""
        self._last_radar: RadarGaze | None = None
        """The last radar direction posted (under `_cond`), likewise."""
        self._cond = threading.Condition()
        self._lock = threading.Lock()
        """Guards `behaviour` and the publishers' order: the decision thread and the
        face callback both decide."""
        self._sounds: queue.Queue[SoundCommand | None] = queue.Queue()
        self._warn = RateLimitedLog(log)
        self._expression_pub = node.publisher(keys.BEHAVIOUR_EXPRESSION)
        self._control_pub = node.publisher(keys.BEHAVIOUR_GAZE)
        self._state_pub = node.publisher(keys.CONTROLLER_STATE)
        self._state: tuple[State, tuple[m.Resource, ...]] | None = None  # the last one put
        self._threads: list[threading.Thread] = []
        self._last_diag = 0.0

    # -- lifetime --

    def apply_settings(self, settings: ControllerSettings) -> None:
        """A live parameter change (`buddybot param set controller ...`): the
        behaviour reads `self.s` on every decision, so the next one uses it.
        Fields read once at start (camera, transform, tick, call timeout,
        recovery) are restart-only in settings.py."""
        with self._lock:
            self.settings = settings
            self.behaviour.s = settings

    def start(self) -> None:
        node = self.node
        node.subscribe(keys.PEOPLE_STATE, self._on_people)
        node.subscribe(keys.DEVICE_FREE, self._on_device_free)
        node.subscribe(keys.PLAY_SOUND_STATUS, self._on_status)
        node.subscribe(keys.FACE, self._on_face, camera=self.settings.camera)
        node.subscribe(keys.LEASES, self._on_leases)
        with self._lock:
            self._publish_state(self.clock())  # the first one, even before any input
        for target, name in ((self._decide, "decide"), (self._sound_worker, "sound")):
            thread = threading.Thread(target=target, name=f"controller:{name}", daemon=True)
            thread.start()
            self._threads.append(thread)

    def close(self) -> None:
        self.node.stop()
        self._sounds.put(None)
        with self._cond:
            self._cond.notify_all()
        for thread in self._threads:
            thread.join(5.0)

    # -- Zenoh callbacks: enqueue only --

    def _post(self, event: Event) -> None:
        """Hand an event to the decision thread (any thread; never blocks)."""
        with self._cond:
            self._inbox.append(event)
            self._cond.notify()

    def _on_people(self, msg: m.PeopleState, _key: str) -> None:
        # `people/state` changes with every face frame of a visitor (distance,
        # direction); only a change of who is in range, or of the followed
        # person's radar direction, is news for the behaviour.
        with self._cond:
            follow = None if self._last_people is None else self._last_people.person_id
            change = people_changed(msg, follow)
            point = radar_point(msg, change.person_id)
            gaze = None
            if point is not None:
                try:
                    gaze = face_gaze(self.transform, point)
                except ValueError:  # cannot happen with a valid message; never NaN gaze
                    gaze = None
            radar = RadarGaze(gaze, msg.stamp_ns if gaze is not None else None)
            news = False
            if change != self._last_people:
                self._last_people = change
                self._inbox.append(change)
                news = True
            if radar.gaze != (None if self._last_radar is None else self._last_radar.gaze):
                self._last_radar = radar
                self._inbox.append(radar)
                news = True
            if news:
                self._cond.notify()

    def _on_device_free(self, msg: m.Bool, _key: str) -> None:
        self._post(DeviceFree(msg.data))

    def _on_status(self, msg: m.PlaySoundStatus, _key: str) -> None:
        # The age lets a restarted controller tell a fresh latched status from an old one.
        age = (m.now_ns() - msg.stamp_ns) / 1e9 if msg.stamp_ns > 0 else None
        self._post(SoundStatus(msg.goal_id, msg.state, age))

    def _on_leases(self, msg: m.Leases, _key: str) -> None:
        self._post(yielded(msg))

    def _on_face(self, msg: m.FacePosition, _key: str) -> None:
        with self._lock:
            now = self.clock()
            self._handle_face(msg, now)
            self._publish_state(now)

    # -- decision thread --

    def _decide(self) -> None:
        stop = self.node.stop_event
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
                self.node.diagnostics.increment("decision_errors")
                self._warn.warning("decide", "decision step failed: %r", exc)

    def decision_step(self, events: list[Event], next_tick: float) -> float:
        """Hand `events` to the behaviour, tick it when `next_tick` has come, publish
        what changed; returns when the next tick is due. The decision thread runs
        this, and pure tests drive it with a fake clock and node."""
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
                                   held=held):
                    commands = b.presence(now, in_range, person_id, name, held)
                case RadarGaze(gaze=gaze, stamp_ns=stamp_ns):
                    commands = b.radar(now, gaze, stamp_ns)
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

    def _handle_face(self, msg: m.FacePosition, arrived: float) -> None:
        p = msg.point
        try:
            gaze = face_gaze(self.transform, (p.x, p.y, p.z))
        except ValueError as exc:
            self.node.diagnostics.increment("bad_faces")
            self._warn.warning("face", "ignored face: %s", exc)
            return
        self._execute(self.behaviour.face(arrived, gaze, msg.stamp_ns))

    def _execute(self, commands: list[Command]) -> None:
        """Carry out the behaviour's commands. Exhaustive: a `Command` member without a
        case fails type checking at `assert_never`, and at run time it raises instead
        of being taken for a sound."""
        for cmd in commands:
            match cmd:
                case Look():
                    self._control_pub.put(self._eye_control(cmd))
                case SetExpression(action=action):
                    log.info("expression -> %s", action.name)
                    self._expression_pub.put(m.ScreenExpression(stamp_ns=m.now_ns(),
                                                                action=action))
                case PlaySound() | CancelSound():
                    self._sounds.put(cmd)
                case _:
                    assert_never(cmd)

    def _eye_control(self, cmd: Look) -> m.EyeControl:
        stamp = cmd.stamp_ns if cmd.stamp_ns is not None else m.now_ns()
        if cmd.gaze is None:
            return m.EyeControl(stamp_ns=stamp, yaw=0.0, pitch=0.0,
                                target_distance_cm=self.settings.centre_distance_cm)
        g = cmd.gaze
        return m.EyeControl(stamp_ns=stamp, yaw=_clamp(g.yaw, math.pi),
                            pitch=_clamp(g.pitch, math.pi / 2), target_distance_cm=g.distance_cm)

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
        values = self.node.diagnostics.values
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
            if cmd is None or self.node.stop_event.is_set():
                return
            self.call_audio(cmd)

    def call_audio(self, cmd: SoundCommand) -> None:
        """Make one blocking audio call and post its answer to the inbox; a failed
        call is answered too (refused, not successful), so the behaviour never waits
        for a reply that cannot come."""
        timeout = self.settings.call_timeout_s
        match cmd:
            case PlaySound(sound=sound, request=request):
                log.info("play_sound %r", sound)
                try:
                    reply = self.node.call(keys.PLAY_SOUND, m.PlaySound(sound=sound),
                                           timeout=timeout)
                    if not reply.accepted:
                        log.warning("play_sound %r refused: %s", sound, reply.message)
                    self._post(GoalReply(request, reply.accepted, reply.goal_id))
                except Exception as exc:  # ServiceError, or Zenoh failing: always answer
                    self.node.diagnostics.increment("sound_call_failures")
                    log.warning("play_sound %r failed: %s", sound, exc)
                    self._post(GoalReply(request, False, ""))
            case CancelSound(goal_id=goal_id):
                log.info("cancel goal %s", goal_id)
                try:
                    answer = self.node.call(keys.PLAY_SOUND_CANCEL,
                                            m.CancelGoal(goal_id=goal_id), timeout=timeout)
                    self._post(CancelReply(goal_id, answer.success))
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
    camera_transform(settings)  # refuse a bad config before connecting
    node = ctx.node()
    controller: Controller | None = None
    try:
        controller = Controller(node, settings)
        LiveSettings(settings, controller.apply_settings).serve(node)
        controller.start()
        node.spin()
    finally:
        if controller is not None:
            controller.close()
        node.close()
    return 0
