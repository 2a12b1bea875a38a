"""Persons from radar presence and the camera's face: a pure state machine.

Inputs are typed samples with the stamp of their sensor data (`RadarSeen`,
`FaceSeen`) and `Tick`s that let timers fire; `PeopleModel.step` returns the
`PersonEvent`s they cause and `state()` the persons now present. Nothing
here knows Zenoh, threads or a clock: time is what the inputs say.

Who is there. The LD2410 sees the nearest person and the face detector
follows one face, so the model holds one person per visit (the types carry
ids and tuples, ready for several). The radar is a level (IN_RANGE holds
until OUT_OF_RANGE, as `radar/presence` is published on change only); the
camera sees a person while its last face is younger than `face_timeout_s`.
A person arrives with the first sample that shows someone and leaves once
neither sensor has shown them for `absence_hold_s`: a flicker shorter than
that is the same person, a return after it is a new person with a new id.

Where. The distance is the camera's while it sees the face (per frame and
precise), otherwise the newest measurement of either sensor; the zone
follows it with hysteresis (`zones.zone_after`).

Engagement (ROS4HRI style), re-evaluated on every input and timer:

    NONE --face in social zone--> ENGAGING --engage_dwell_s--> ENGAGED
    ENGAGING --face lost or zone PUBLIC--> NONE
    ENGAGED --face lost or zone PUBLIC--> DISENGAGING --face back--> ENGAGED
    DISENGAGING --disengage_hold_s--> NONE
    any --absence_hold_s with neither sensor--> GONE, then LEFT

Time. Timers fire at their deadline, computed from sensor stamps (the last
face + `face_timeout_s`, the start of a dwell or hold + its length), and
before any input stamped later is applied: with inputs in stamp order the
events, their order and their stamps do not depend on how often `Tick`
comes. Every event carries the stamp of the sensor data that decided it:
an input's own stamp, or a timer's deadline. A sample older than the
previous one of the same sensor is ignored (it would undo newer data); one
older than a `Tick` already seen is applied as it is, keeping its stamp.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import assert_never

from buddybot.people.settings import PeopleSettings
from buddybot.people.zones import Zone, zone_after, zone_of

_NS_PER_S = 1_000_000_000

# --- inputs ----------------------------------------------------------------------------


def _check_sample(stamp_ns: int, distance_m: float) -> None:
    if stamp_ns < 0:
        raise ValueError(f"stamp_ns must be >= 0, not {stamp_ns}")
    if not (math.isfinite(distance_m) and distance_m >= 0.0):
        raise ValueError(f"distance_m must be finite and >= 0, not {distance_m}")


@dataclass(frozen=True, slots=True)
class RadarSeen:
    """Radar presence (`PresenceDetection`): someone in range or not, and the
    nearest target's distance (used only while in range)."""

    stamp_ns: int
    in_range: bool
    distance_m: float

    def __post_init__(self) -> None:
        _check_sample(self.stamp_ns, self.distance_m)


@dataclass(frozen=True, slots=True)
class FaceSeen:
    """The camera's followed face (`FacePosition`): its distance and direction."""

    stamp_ns: int
    distance_m: float
    yaw_rad: float
    """+ = the robot's left."""
    pitch_rad: float
    """+ = up."""

    def __post_init__(self) -> None:
        _check_sample(self.stamp_ns, self.distance_m)
        if not (math.isfinite(self.yaw_rad) and math.isfinite(self.pitch_rad)):
            raise ValueError("yaw_rad and pitch_rad must be finite")


@dataclass(frozen=True, slots=True)
class Tick:
    """Time has reached `now_ns` (same clock as the stamps): timers due fire."""

    now_ns: int


Input = RadarSeen | FaceSeen | Tick

# --- persons -----------------------------------------------------------------------------


class Sensor(enum.Flag):
    """Which sensors show a person now; NONE while they are missed (not yet gone)."""

    NONE = 0
    RADAR = 1
    CAMERA = 2
    BOTH = 3


class Engagement(enum.IntEnum):
    NONE = 0
    ENGAGING = 1
    ENGAGED = 2
    DISENGAGING = 3
    GONE = 4


@dataclass(frozen=True, slots=True)
class Person:
    """One person as the model sees them now (a snapshot)."""

    id: int
    """Counts visits from 1; never reused in a run."""
    distance_m: float
    zone: Zone
    seen_by: Sensor
    zone_since_ns: int
    arrived_ns: int
    """Stamp of the sensor data that first showed them (may be older than the model)."""
    engagement: Engagement
    engagement_since_ns: int
    yaw_rad: float | None = None
    """Direction of their face when the camera last saw it; None: not yet seen."""
    pitch_rad: float | None = None
    name: str | None = None
    """Who they are, once something recognises them."""


# --- events ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Arrived:
    person_id: int
    stamp_ns: int
    person: Person


@dataclass(frozen=True, slots=True)
class ZoneChanged:
    person_id: int
    stamp_ns: int
    zone_from: Zone
    zone_to: Zone
    distance_m: float


@dataclass(frozen=True, slots=True)
class EngagementChanged:
    person_id: int
    stamp_ns: int
    engagement_from: Engagement
    engagement_to: Engagement


@dataclass(frozen=True, slots=True)
class Left:
    """The last event of a person; `person` is their final state (engagement GONE)."""

    person_id: int
    stamp_ns: int
    person: Person


PersonEvent = Arrived | ZoneChanged | EngagementChanged | Left

# --- the model ---------------------------------------------------------------------------


@dataclass
class _Track:
    """A present person, mutable inside the model."""

    id: int
    arrived_ns: int
    distance_m: float
    zone: Zone
    zone_since_ns: int
    seen_by: Sensor
    lost_since_ns: int
    """When `seen_by` became NONE (meaningful only then)."""
    engagement: Engagement
    engagement_since_ns: int
    yaw_rad: float | None
    pitch_rad: float | None

    def person(self) -> Person:
        return Person(id=self.id, distance_m=self.distance_m, zone=self.zone,
                      seen_by=self.seen_by, zone_since_ns=self.zone_since_ns,
                      arrived_ns=self.arrived_ns, engagement=self.engagement,
                      engagement_since_ns=self.engagement_since_ns,
                      yaw_rad=self.yaw_rad, pitch_rad=self.pitch_rad)


def _ns(seconds: float) -> int:
    return round(seconds * _NS_PER_S)


class PeopleModel:
    """Fuses radar presence and the followed face into persons; single-threaded."""

    def __init__(self, settings: PeopleSettings) -> None:
        self.s = settings
        self._now: int | None = None
        """The newest time seen (stamps and ticks); it never goes back."""
        self._radar: RadarSeen | None = None
        self._face: FaceSeen | None = None
        self._track: _Track | None = None
        self._last_id = 0

    def state(self) -> tuple[Person, ...]:
        """The persons present now (seen, or missed for less than `absence_hold_s`)."""
        return () if self._track is None else (self._track.person(),)

    def step(self, event: Input) -> list[PersonEvent]:
        """Apply one input; the events it causes, in order."""
        match event:
            case Tick():
                return self._advance(event.now_ns)
            case RadarSeen():
                if self._radar is not None and event.stamp_ns < self._radar.stamp_ns:
                    return []
                out = self._advance(event.stamp_ns)
                self._radar = event
                return out + self._sensed(event.stamp_ns,
                                          event.distance_m if event.in_range else None, None)
            case FaceSeen():
                if self._face is not None and event.stamp_ns < self._face.stamp_ns:
                    return []
                out = self._advance(event.stamp_ns)
                self._face = event
                return out + self._sensed(event.stamp_ns, event.distance_m, event)
            case _:
                assert_never(event)

    # -- time --

    def _advance(self, to_ns: int) -> list[PersonEvent]:
        """Fire every timer due up to `to_ns`, each at its deadline, in order."""
        target = to_ns if self._now is None else max(self._now, to_ns)
        out: list[PersonEvent] = []
        while (deadline := self._next_deadline()) is not None and deadline <= target:
            at = deadline if self._now is None else max(self._now, deadline)
            self._now = at
            out += self._evaluate(at, deadline)
        self._now = target
        return out

    def _next_deadline(self) -> int | None:
        """When the present person's state may change next without input."""
        track = self._track
        if track is None:
            return None
        due: list[int] = []
        if Sensor.CAMERA in track.seen_by and self._face is not None:
            due.append(self._face.stamp_ns + _ns(self.s.face_timeout_s))
        if track.engagement is Engagement.ENGAGING:
            due.append(track.engagement_since_ns + _ns(self.s.engage_dwell_s))
        elif track.engagement is Engagement.DISENGAGING:
            due.append(track.engagement_since_ns + _ns(self.s.disengage_hold_s))
        if not track.seen_by:
            due.append(track.lost_since_ns + _ns(self.s.absence_hold_s))
        return min(due, default=None)

    def _seen_by(self, at: int) -> Sensor:
        seen = Sensor.NONE
        if self._radar is not None and self._radar.in_range:
            seen |= Sensor.RADAR
        if self._face is not None and at < self._face.stamp_ns + _ns(self.s.face_timeout_s):
            seen |= Sensor.CAMERA
        return seen

    # -- inputs --

    def _sensed(self, stamp: int, distance_m: float | None,
                face: FaceSeen | None) -> list[PersonEvent]:
        """A sample was taken: arrival, distance and zone, then the state."""
        assert self._now is not None  # _advance ran
        at = self._now
        seen = self._seen_by(at)
        source = Sensor.CAMERA if face is not None else Sensor.RADAR
        # The radar's distance counts only while the camera does not see the face.
        trusted = Sensor.CAMERA if Sensor.CAMERA in seen else Sensor.RADAR
        measured = distance_m if source is trusted and source in seen else None
        out: list[PersonEvent] = []
        track = self._track
        if track is None:
            if measured is None:
                return []
            track = self._arrive(stamp, measured, seen)
            out.append(Arrived(track.id, stamp, track.person()))
        elif measured is not None:
            out += self._move(track, stamp, measured)
        if face is not None and Sensor.CAMERA in seen:
            track.yaw_rad, track.pitch_rad = face.yaw_rad, face.pitch_rad
        return out + self._evaluate(at, stamp)

    def _arrive(self, stamp: int, distance_m: float, seen: Sensor) -> _Track:
        self._last_id += 1
        self._track = _Track(
            id=self._last_id, arrived_ns=stamp, distance_m=distance_m,
            zone=zone_of(distance_m, self.s), zone_since_ns=stamp, seen_by=seen,
            lost_since_ns=stamp, engagement=Engagement.NONE, engagement_since_ns=stamp,
            yaw_rad=None, pitch_rad=None)
        return self._track

    def _move(self, track: _Track, stamp: int, distance_m: float) -> list[PersonEvent]:
        track.distance_m = distance_m
        zone = zone_after(track.zone, distance_m, self.s)
        if zone is track.zone:
            return []
        event = ZoneChanged(track.id, stamp, track.zone, zone, distance_m)
        track.zone, track.zone_since_ns = zone, stamp
        return [event]

    # -- state --

    def _evaluate(self, at: int, stamp: int) -> list[PersonEvent]:
        """Bring the present person's sensors, presence and engagement up to time
        `at`; changes are stamped `stamp`, or a hold's end if that is later."""
        track = self._track
        if track is None:
            return []
        seen = self._seen_by(at)
        if seen != track.seen_by:
            if not seen:
                track.lost_since_ns = stamp
            track.seen_by = seen
        if not seen:
            gone_at = track.lost_since_ns + _ns(self.s.absence_hold_s)
            if at >= gone_at:
                return self._leave(track, max(stamp, gone_at))
        return self._engage(track, at, stamp)

    def _engage(self, track: _Track, at: int, stamp: int) -> list[PersonEvent]:
        attending = Sensor.CAMERA in track.seen_by and track.zone <= Zone.SOCIAL
        out: list[PersonEvent] = []
        while True:
            was, since = track.engagement, track.engagement_since_ns
            new, when = was, stamp
            if was is Engagement.NONE and attending:
                new = Engagement.ENGAGING
            elif was is Engagement.ENGAGING:
                dwelt = since + _ns(self.s.engage_dwell_s)
                if not attending:
                    new = Engagement.NONE
                elif at >= dwelt:
                    new, when = Engagement.ENGAGED, max(stamp, dwelt)
            elif was is Engagement.ENGAGED and not attending:
                new = Engagement.DISENGAGING
            elif was is Engagement.DISENGAGING:
                held = since + _ns(self.s.disengage_hold_s)
                if attending:
                    new = Engagement.ENGAGED
                elif at >= held:
                    new, when = Engagement.NONE, max(stamp, held)
            if new is was:
                return out
            out.append(EngagementChanged(track.id, when, was, new))
            track.engagement, track.engagement_since_ns = new, when

    def _leave(self, track: _Track, stamp: int) -> list[PersonEvent]:
        out: list[PersonEvent] = [
            EngagementChanged(track.id, stamp, track.engagement, Engagement.GONE)]
        track.engagement, track.engagement_since_ns = Engagement.GONE, stamp
        out.append(Left(track.id, stamp, track.person()))
        self._track = None
        return out
