"""`buddybot run people`: the thin adapter between Zenoh and `model.PeopleModel`.

Reads `radar/presence` (latched), `radar/*/targets` (every angle-radar
report), `camera/<camera>/face` and `identity/<camera>/name` (latched: the
identity service's name for the followed face, if it runs), turns each message into the model's
input with the message's own stamp, and runs a `Tick` every `tick_s` so
holds and timeouts fire without input. Every event the model returns goes
out on `people/events` at once, in order; the persons present go out on
`people/state` (latched) whenever they differ from the last ones published
(once at start, empty, so a reader learns that nobody is there), a change
only of where they are at most every `position_period_s` (`pacing.py`).

Threads: the three subscriptions run inline in Zenoh's callback thread (a
step takes microseconds and its puts do not block) and the ticks on the
node's timer thread; one lock serialises the model and the publishers, so
the events leave in the model's order. A malformed message never reaches
this module: the node drops and counts it (`malformed` in diagnostics). A
face whose distance the contract cannot carry (beyond 1000 m) is dropped
here and counted as `bad_faces`.

Ticks carry the wall clock (the stamps' clock); the events of a timer
carry its deadline computed from sensor stamps, not the tick's time
(docs/people.md, "Time").
"""

from __future__ import annotations

import argparse
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import assert_never

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.people.model import (
    Arrived,
    Engagement,
    EngagementChanged,
    FaceSeen,
    Input,
    Left,
    NameSeen,
    PeopleModel,
    Person,
    PersonEvent,
    RadarSeen,
    RangeSeen,
    Sensor,
    TargetsSeen,
    Tick,
    ZoneChanged,
)
from buddybot.people.pacing import StatePacer
from buddybot.people.settings import PeopleSettings
from buddybot.people.tracker import Target
from buddybot.people.zones import Zone
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext

log = logging.getLogger("buddybot.people")

MAX_DISTANCE_M = 1000.0
"""The largest distance `Person.distance_m` carries (the contract's `Metres`)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The option overrides its `[people]` key (default: settings.py)."""
    settings_option(parser, "--camera", struct=PeopleSettings, field="camera", metavar="NAME")


def settings_from(ctx: ServiceContext) -> PeopleSettings:
    """`[people]` with the command line on top, the camera name checked."""
    settings = merge(ctx.config.section(PeopleSettings), ctx.args)
    if not keys.valid_robot_id(settings.camera):
        raise ConfigError(f"[people] camera: invalid camera name {settings.camera!r}")
    return settings


# --- messages -> model inputs (pure) ------------------------------------------------------


def radar_seen(msg: m.PresenceDetection) -> RadarSeen:
    return RadarSeen(stamp_ns=msg.stamp_ns,
                     in_range=msg.presence_state == m.PresenceState.IN_RANGE,
                     distance_m=msg.distance_m)


def ranges_seen(msg: m.LD2410TargetDataFrameArray) -> list[RangeSeen]:
    """Each sensor's nearest target in one LD2410 report, read by the contract's
    rule (None: it sees nobody, or it measures its background noise)."""
    out = []
    for f in msg.sensors:
        cm = m.target_distance_cm(int(f.target_state), f.detection_distance,
                                  f.movement_distance, f.stationary_distance)
        out.append(RangeSeen(msg.stamp_ns, (msg.device_id, f.radar_id),
                             cm / 100.0 if cm > 0 else None))
    return out


def face_seen(msg: m.FacePosition) -> FaceSeen:
    """The face's distance from the camera and its direction (ROS axes: x forward,
    y left, z up, so + yaw = the robot's left, + pitch = up). ValueError when the
    distance is beyond what a `Person` carries."""
    x, y, z = msg.point.x, msg.point.y, msg.point.z
    distance = math.sqrt(x * x + y * y + z * z)
    if distance > MAX_DISTANCE_M:
        raise ValueError(f"face {distance:.0f} m away (limit {MAX_DISTANCE_M:.0f} m)")
    return FaceSeen(stamp_ns=msg.stamp_ns, distance_m=distance,
                    yaw_rad=math.atan2(y, x), pitch_rad=math.atan2(z, math.hypot(x, y)),
                    track=msg.track)


def name_seen(msg: m.FaceName) -> NameSeen:
    return NameSeen(stamp_ns=msg.stamp_ns, track=msg.track, name=msg.name)


def targets_seen(msg: m.RadarTargets) -> TargetsSeen:
    """An angle-radar report: each target's position in the camera's frame (its
    height is dropped: the tracker works on the floor plan)."""
    return TargetsSeen(
        stamp_ns=msg.stamp_ns, sensor=(msg.device_id, msg.radar_id),
        targets=tuple(Target(t.position.x, t.position.y) for t in msg.targets))


# --- model -> messages (pure) -------------------------------------------------------------


# Written out, so renaming a member of the model cannot change the contract.
ZONES: dict[Zone, m.Zone] = {
    Zone.INTIMATE: "INTIMATE", Zone.PERSONAL: "PERSONAL", Zone.SOCIAL: "SOCIAL",
    Zone.PUBLIC: "PUBLIC"}
SENSORS: dict[Sensor, m.SeenBy] = {
    Sensor.NONE: "NONE", Sensor.RADAR: "RADAR", Sensor.CAMERA: "CAMERA", Sensor.BOTH: "BOTH"}
ENGAGEMENTS: dict[Engagement, m.Engagement] = {
    Engagement.NONE: "NONE", Engagement.ENGAGING: "ENGAGING", Engagement.ENGAGED: "ENGAGED",
    Engagement.DISENGAGING: "DISENGAGING", Engagement.GONE: "GONE"}
KINDS: dict[type, m.PersonEventKind] = {
    Arrived: "ARRIVED", ZoneChanged: "ZONE_CHANGED",
    EngagementChanged: "ENGAGEMENT_CHANGED", Left: "LEFT"}


def person_message(p: Person) -> m.Person:
    return m.Person(
        id=p.id, distance_m=p.distance_m, zone=ZONES[p.zone], seen_by=SENSORS[p.seen_by],
        zone_since_ns=p.zone_since_ns, arrived_ns=p.arrived_ns,
        engagement=ENGAGEMENTS[p.engagement], engagement_since_ns=p.engagement_since_ns,
        yaw_rad=p.yaw_rad, pitch_rad=p.pitch_rad, name=p.name, bearing_rad=p.bearing_rad)


def state_message(people: tuple[Person, ...], stamp_ns: int) -> m.PeopleState:
    return m.PeopleState(stamp_ns=stamp_ns, people=[person_message(p) for p in people])


def event_messages(events: list[PersonEvent],
                   before: tuple[Person, ...]) -> list[m.PersonEvent]:
    """The model's events of one step as messages, each with the person's zone and
    engagement right after it: `before` is the state the step started from (a zone
    change and an engagement change of one step see each other's result)."""
    now = {p.id: (p.zone, p.engagement) for p in before}
    out: list[m.PersonEvent] = []
    for event in events:
        match event:
            case Arrived(person=p) | Left(person=p):
                zone, engagement = p.zone, p.engagement
            case ZoneChanged(zone_to=to):
                zone, engagement = to, now[event.person_id][1]
            case EngagementChanged(engagement_to=to):
                zone, engagement = now[event.person_id][0], to
            case _:
                assert_never(event)
        now[event.person_id] = (zone, engagement)
        out.append(m.PersonEvent(stamp_ns=event.stamp_ns, person_id=event.person_id,
                                 kind=KINDS[type(event)], zone=ZONES[zone],
                                 engagement=ENGAGEMENTS[engagement]))
    return out


def state_stamp(given: Input, events: list[PersonEvent]) -> int:
    """The stamp of a state changed by `given`: the sensor sample's (or its newest
    event's, if a timer fired later), or for a tick its newest event's, else the
    tick's time."""
    newest = max((e.stamp_ns for e in events), default=None)
    if isinstance(given, Tick):
        return given.now_ns if newest is None else newest
    return given.stamp_ns if newest is None else max(newest, given.stamp_ns)


# --- the service ---------------------------------------------------------------------------


class PeopleService:
    """Wires one Node to one PeopleModel; `start()` declares everything."""

    def __init__(self, node: Node, settings: PeopleSettings,
                 clock: Callable[[], float] = time.monotonic) -> None:
        """`clock`: seconds, for the pacing of `people/state` only (the model runs
        on the sensors' stamps)."""
        self.node = node
        self._clock = clock
        self.settings = settings
        self.model = PeopleModel(settings)
        self._lock = threading.Lock()
        """Guards the model and the publishers' order."""
        self._events_pub = node.publisher(keys.PEOPLE_EVENTS)
        self._state_pub = node.publisher(keys.PEOPLE_STATE)
        self._pacer = StatePacer()
        self._events = 0

    def apply_settings(self, settings: PeopleSettings) -> None:
        """A live parameter change (`buddybot param set people ...`): the model reads
        its settings on every input and tick, so the next one uses them. `camera`
        and `tick_s` are read once at start (restart-only)."""
        with self._lock:
            self.model.s = settings

    def start(self) -> None:
        with self._lock:
            self._publish_state(m.now_ns())
        self.node.subscribe(keys.PRESENCE, self._on_presence)
        self.node.subscribe(keys.RADAR_TARGETS, self._on_targets, device="*")
        self.node.subscribe(keys.RADAR_FRAMES, self._on_frames, device="*")
        self.node.subscribe(keys.FACE, self._on_face, camera=self.settings.camera)
        self.node.subscribe(keys.FACE_NAME, self._on_name, camera=self.settings.camera)
        self.node.every(self.settings.tick_s, self.tick, name="people-tick")

    def _on_presence(self, msg: m.PresenceDetection, _key: str) -> None:
        self.step(radar_seen(msg))

    def _on_frames(self, msg: m.LD2410TargetDataFrameArray, _key: str) -> None:
        for seen in ranges_seen(msg):
            self.step(seen)

    def _on_targets(self, msg: m.RadarTargets, _key: str) -> None:
        try:
            seen = targets_seen(msg)
        except ValueError as exc:  # a non-finite position
            self.node.diagnostics.increment("bad_targets")
            log.debug("ignored radar targets: %s", exc)
            return
        self.step(seen)

    def _on_face(self, msg: m.FacePosition, _key: str) -> None:
        try:
            face = face_seen(msg)
        except ValueError as exc:
            self.node.diagnostics.increment("bad_faces")
            log.debug("ignored face: %s", exc)
            return
        self.step(face)

    def _on_name(self, msg: m.FaceName, _key: str) -> None:
        try:
            seen = name_seen(msg)
        except ValueError as exc:  # a blank name
            self.node.diagnostics.increment("bad_names")
            log.debug("ignored face name: %s", exc)
            return
        self.step(seen)

    def tick(self) -> None:
        self.step(Tick(m.now_ns()))
        values = self.node.diagnostics.values
        values["people"] = len(self._pacer.published or ())
        values["events"] = self._events
        values["tracks_refused"] = self.model.tracks_refused
        values["people_refused"] = self.model.refused
        values["clutter"] = self.model.clutter

    def step(self, given: Input) -> None:
        """Feed one input; publish its events, then the state if it changed."""
        with self._lock:
            before = self.model.state()
            events = self.model.step(given)
            for msg in event_messages(events, before):
                log.info("person %d %s: %s, %s", msg.person_id, msg.kind, msg.zone,
                         msg.engagement)
                self._events_pub.put(msg)
            self._events += len(events)
            self._publish_state(state_stamp(given, events))

    def _publish_state(self, stamp_ns: int) -> None:
        """Put `people/state` if the persons changed and the pacer lets it go
        now; under the lock."""
        people = self.model.state()
        stamp = self._pacer.offer(people, stamp_ns, self._clock(),
                                  self.model.s.position_period_s)
        if stamp is not None:
            self._state_pub.put(state_message(people, stamp))


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)  # refuse a bad config before connecting
    node = ctx.node()
    try:
        service = PeopleService(node, settings)
        LiveSettings(settings, service.apply_settings).serve(node)
        service.start()
        node.spin()
    finally:
        node.close()
    return 0
