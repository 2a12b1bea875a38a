"""Persons from radar presence and the camera's face: a pure state machine.

Inputs are typed samples with the stamp of their sensor data (`RadarSeen`,
`FaceSeen`, `TargetsSeen` from angle radars, `NameSeen` from the identity
service) and `Tick`s that let timers fire; `PeopleModel.step` returns the
`PersonEvent`s they cause and `state()` the persons now present. Nothing
here knows Zenoh, threads or a clock: time is what the inputs say, so the
events do not depend on how often `Tick` comes.

One untracked person per visit without angle radars; one tracked person
per radar track with them, the followed face fused to the track in its
direction. Names follow the face that was given them; engagement is
ROS4HRI style. At most `MAX_PEOPLE` persons.

Rationale: docs/people.md, 'What the model decides, and why', 'Angle
radars: tracks, fusion with the face', 'Engagement' and 'Names'.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import assert_never

from buddybot.contract.messages import MAX_PEOPLE
from buddybot.people.clutter import Point, Spots
from buddybot.people.settings import PeopleSettings
from buddybot.people.tracker import Report, SensorId, Target, Tracker, TrackerLimits
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
    track: int | None = None
    """The detector's track of the face (None: a source without ids): a name is
    only ever on the face of the track that was given it."""

    def __post_init__(self) -> None:
        _check_sample(self.stamp_ns, self.distance_m)
        if not (math.isfinite(self.yaw_rad) and math.isfinite(self.pitch_rad)):
            raise ValueError("yaw_rad and pitch_rad must be finite")


@dataclass(frozen=True, slots=True)
class Tick:
    """Time has reached `now_ns` (same clock as the stamps): timers due fire."""

    now_ns: int


@dataclass(frozen=True, slots=True)
class TargetsSeen:
    """One angle-radar report (`RadarTargets`): its targets in the camera's frame."""

    stamp_ns: int
    sensor: SensorId
    """(device_id, radar_id)."""
    targets: tuple[Target, ...]

    def __post_init__(self) -> None:
        _check_sample(self.stamp_ns, 0.0)


@dataclass(frozen=True, slots=True)
class NameSeen:
    """Who the followed face is (`FaceName`): its face track (None: no face
    followed) and that track's name (None: unknown, not yet decided, or forgotten)."""

    stamp_ns: int
    track: int | None
    name: str | None

    def __post_init__(self) -> None:
        _check_sample(self.stamp_ns, 0.0)
        if self.name is not None and not self.name.strip():
            raise ValueError("name must not be empty")


@dataclass(frozen=True, slots=True)
class RangeSeen:
    """One LD2410 frame (`LD2410TargetDataFrame`): the distance of its nearest
    target, None when it sees nobody. Radar presence says whether someone is in
    range; these say whether what it sees moves through the room (clutter)."""

    stamp_ns: int
    sensor: SensorId
    """(device_id, radar_id)."""
    distance_m: float | None

    def __post_init__(self) -> None:
        _check_sample(self.stamp_ns, 0.0 if self.distance_m is None else self.distance_m)


Input = RadarSeen | RangeSeen | FaceSeen | TargetsSeen | NameSeen | Tick

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
    """Their direction: the face's when the camera last saw it, for a tracked person
    the radar's bearing while the camera does not see them; None: not yet known."""
    pitch_rad: float | None = None
    name: str | None = None
    """Who they are, once something recognises them."""
    bearing_rad: float | None = None
    """The bearing of their angle-radar track now (+ = left); None: no track."""


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
    attending: bool
    attending_since_ns: int
    """Whether they attend (face seen, social zone or nearer), and since when: the
    engagement's dwell and look-away count from it."""
    yaw_rad: float | None
    pitch_rad: float | None
    track_id: int | None = None
    """Their radar track (None: the untracked person of radar presence and the face)."""
    radar_xy: tuple[float, float] | None = None
    """Where their track was last (kept after it is dropped, to continue it)."""
    bearing_rad: float | None = None
    radar_last_ns: int | None = None
    """When their radar track last matched a report (None: no track yet)."""
    origin: Point | None = None
    """Where the radar first showed them (an LD2410's distance as (d, 0))."""
    real: bool = False
    """Shown to be a person: the camera saw them, or the radar showed them move more
    than `clutter_spread_m` from `origin`. Else, after `clutter_after_s`, clutter."""
    name: str | None = None
    name_track: int | None = None
    """The face track whose name `name` is (None: no name)."""

    def person(self) -> Person:
        return Person(id=self.id, distance_m=self.distance_m, zone=self.zone,
                      seen_by=self.seen_by, zone_since_ns=self.zone_since_ns,
                      arrived_ns=self.arrived_ns, engagement=self.engagement,
                      engagement_since_ns=self.engagement_since_ns,
                      yaw_rad=self.yaw_rad, pitch_rad=self.pitch_rad,
                      name=self.name, bearing_rad=self.bearing_rad)


def _unname(person: _Track) -> None:
    person.name, person.name_track = None, None


def _ns(seconds: float) -> int:
    return round(seconds * _NS_PER_S)


def _angle_between(a: float, b: float) -> float:
    """|a - b| wrapped into [0, pi]."""
    return abs(math.remainder(a - b, math.tau))


_MAX_SENSORS = 64
"""Angle radars whose last stamp is remembered (the oldest is forgotten)."""


class PeopleModel:
    """Fuses radar presence, angle-radar tracks and the followed face into persons;
    single-threaded."""

    def __init__(self, settings: PeopleSettings) -> None:
        self.s = settings
        self._now: int | None = None
        """The newest time seen (stamps and ticks); it never goes back."""
        self._radar: RadarSeen | None = None
        self._ranges: dict[SensorId, tuple[int, float | None]] = {}
        """Each LD2410's newest frame: (stamp, nearest distance or None)."""
        self._range_clutter = False
        """The LD2410s' nearest target is at a clutter spot now."""
        self._spots = Spots(settings.clutter_spread_m, _ns(settings.clutter_after_s))
        """Clutter spots of angle radars (floor plan)."""
        self._range_spots = Spots(settings.clutter_spread_m, _ns(settings.clutter_after_s))
        """Clutter spots of LD2410s: (distance, 0)."""
        self._clutter_tracks: set[int] = set()
        """Radar tracks at clutter spots: no person."""
        self.clutter = 0
        """Persons found to be clutter."""
        self._radar_lost_ns: int | None = None
        """The stamp of the last OUT_OF_RANGE after IN_RANGE: the absence's first frame."""
        self._face: FaceSeen | None = None
        self._face_holder: int | None = None
        """The tracked person the face belongs to; None: the untracked person."""
        self._persons: dict[int, _Track] = {}
        self._untracked: int | None = None
        """The id of the person radar presence and unmatched faces show, if present."""
        self._tracker = Tracker(self._limits())
        self._reports: dict[SensorId, int] = {}
        """Each angle radar's newest report stamp."""
        self._angle_until: int | None = None
        """Angle radars count as reporting until then."""
        self._name: NameSeen | None = None
        """The newest `NameSeen` with a name that no face held yet (given at the next face)."""
        self._name_stamp: int | None = None
        self._last_id = 0
        self._stamps: dict[int, int] = {}
        """Each present person's newest event stamp."""
        self.refused = 0
        """Arrivals refused because `MAX_PEOPLE` were present."""

    def state(self) -> tuple[Person, ...]:
        """The persons present now (seen, or last shown by a sensor less than
        `absence_hold_s` ago), by id."""
        return tuple(self._persons[i].person() for i in sorted(self._persons))

    def step(self, event: Input) -> list[PersonEvent]:
        """Apply one input; the events it causes, in order, each person's stamps never
        going back (an input stamped before a hold's end may follow the hold's event)."""
        out = []
        for e in self._step(event):
            last = self._stamps.get(e.person_id, e.stamp_ns)
            if e.stamp_ns < last:
                e = dataclasses.replace(e, stamp_ns=last)
            self._stamps[e.person_id] = e.stamp_ns
            if isinstance(e, Left):
                del self._stamps[e.person_id]
            out.append(e)
        return out

    def _step(self, event: Input) -> list[PersonEvent]:
        match event:
            case Tick():
                return self._advance(event.now_ns)
            case RadarSeen():
                if self._radar is not None and event.stamp_ns < self._radar.stamp_ns:
                    return []
                out = self._advance(event.stamp_ns)
                if self._radar is not None and self._radar.in_range and not event.in_range:
                    self._radar_lost_ns = event.stamp_ns
                self._radar = event
                return out + self._sensed(event.stamp_ns,
                                          event.distance_m if event.in_range else None, None)
            case FaceSeen():
                if self._face is not None and event.stamp_ns < self._face.stamp_ns:
                    return []
                out = self._advance(event.stamp_ns)
                self._face = event
                self._face_holder = self._holder(event)
                if self._face_holder is None:
                    out += self._sensed(event.stamp_ns, event.distance_m, event)
                else:
                    out += self._face_on(self._persons[self._face_holder], event)
                self._unname_other_face(event)
                self._name_face()
                return out
            case RangeSeen():
                last_range = self._ranges.get(event.sensor)
                if last_range is not None and event.stamp_ns < last_range[0]:
                    return []
                out = self._advance(event.stamp_ns)
                return out + self._ranged(event)
            case TargetsSeen():
                last = self._reports.get(event.sensor)
                if last is not None and event.stamp_ns < last:
                    return []
                out = self._advance(event.stamp_ns)
                self._remember_report(event)
                self._tracker.limits = self._limits()
                started = self._tracker.update(
                    Report(event.stamp_ns, event.sensor, event.targets))
                return out + self._tracked(event.stamp_ns, started)
            case NameSeen():
                if self._name_stamp is not None and event.stamp_ns < self._name_stamp:
                    return []
                out = self._advance(event.stamp_ns)
                self._name, self._name_stamp = event, event.stamp_ns
                self._unname_forgotten(event)
                self._name_face()
                return out
            case _:
                assert_never(event)

    @property
    def tracks_refused(self) -> int:
        """Targets that found no track because `max_tracks` existed."""
        return self._tracker.refused

    def _limits(self) -> TrackerLimits:
        s = self.s
        return TrackerLimits(s.track_gate_m, s.track_coast_s, s.max_tracks)

    # -- clutter --

    def _spots_now(self, at: int, spots: Spots | None = None) -> Spots:
        """The spots (of angle radars, or `spots`) with today's settings, those shown
        nothing for long forgotten."""
        spots = self._spots if spots is None else spots
        spots.spread_m = self.s.clutter_spread_m
        spots.forget_ns = _ns(self.s.clutter_after_s)
        spots.expire(at)
        return spots

    def _nearest_range(self, at: int) -> float | None:
        """The nearest target of the LD2410s heard within `radar_timeout_s`."""
        fresh = [d for stamp, d in self._ranges.values()
                 if d is not None and at - stamp < _ns(self.s.radar_timeout_s)]
        return min(fresh, default=None)

    def _ranged(self, event: RangeSeen) -> list[PersonEvent]:
        """An LD2410 frame: is its nearest target at a clutter spot, and did the
        untracked person the radar shows move through the room."""
        assert self._now is not None
        self._ranges.pop(event.sensor, None)
        self._ranges[event.sensor] = (event.stamp_ns, event.distance_m)
        while len(self._ranges) > _MAX_SENSORS:
            self._ranges.pop(next(iter(self._ranges)))
        nearest = self._nearest_range(self._now)
        spots = self._spots_now(self._now, self._range_spots)
        if nearest is not None:
            spots.hidden(nearest, event.stamp_ns)
        self._range_clutter = nearest is not None and spots.shown((nearest, 0.0),
                                                                  event.stamp_ns)
        person = None if self._untracked is None else self._persons[self._untracked]
        if person is not None and nearest is not None and not self._range_clutter \
                and Sensor.RADAR in person.seen_by:
            self._moved(person, (nearest, 0.0))
        out = self._evaluate(self._now, event.stamp_ns)
        if (self._untracked is None and nearest is not None and not self._range_clutter
                and Sensor.RADAR in self._untracked_seen(self._now)):
            out += self._sensed(event.stamp_ns, nearest, None)
            if self._untracked is not None and len(self._range_spots):
                # Off a spot: someone came through it (the fan hid their approach).
                self._persons[self._untracked].real = True
        return out

    def _moved(self, person: _Track, at: Point) -> None:
        if person.origin is None:
            person.origin = at
        elif math.dist(person.origin, at) > self.s.clutter_spread_m:
            person.real = True

    def _remember_report(self, event: TargetsSeen) -> None:
        self._reports.pop(event.sensor, None)
        self._reports[event.sensor] = event.stamp_ns
        while len(self._reports) > _MAX_SENSORS:
            self._reports.pop(next(iter(self._reports)))
        until = event.stamp_ns + _ns(self.s.radar_timeout_s)
        self._angle_until = until if self._angle_until is None else max(self._angle_until,
                                                                         until)

    # -- names --

    def _face_owner(self) -> _Track | None:
        """The present person the last face belongs to, if any."""
        if self._face is None:
            return None
        if self._face_holder is not None:
            return self._persons[self._face_holder]
        if self._untracked is None:
            return None
        person = self._persons[self._untracked]
        return person if person.arrived_ns <= self._face.stamp_ns else None

    def _unname_forgotten(self, given: NameSeen) -> None:
        """The track that gave a name now has none: the name was taken back. The
        face holder's name from an older track is withdrawn too: their face is on
        a newer, undecided track (ids count up), which may be someone else."""
        if given.track is None or given.name is not None:
            return
        for person in self._persons.values():
            if person.name_track == given.track:
                _unname(person)
        owner = self._face_owner()
        if (owner is not None and owner.name_track is not None
                and owner.name_track < given.track):
            _unname(owner)

    def _unname_other_face(self, face: FaceSeen) -> None:
        """A face of another track than the one its holder's name came from: the
        detector follows someone else now, so the name goes at once, before the
        identity service has seen the new face (a wrong name is worse than none)."""
        owner = self._face_owner()
        if (face.track is not None and owner is not None and owner.name is not None
                and owner.name_track != face.track):
            _unname(owner)

    def _name_face(self) -> None:
        """Give a pending name to the person holding the face, if the face is of the
        track the name was given (or the face has no track id), taking it from
        anyone else; once given it is no longer pending (a later face of someone
        else, before the identity service saw the change, must not take it)."""
        given = self._name
        owner = self._face_owner()
        if given is None or given.name is None or given.track is None or owner is None:
            return
        assert self._face is not None  # an owner holds the face
        if self._face.track is not None and self._face.track != given.track:
            return  # a name of another face: kept until its face comes, or replaced
        self._name = None
        for person in self._persons.values():
            if person.name == given.name:
                _unname(person)
        owner.name, owner.name_track = given.name, given.track

    # -- time --

    def _advance(self, to_ns: int) -> list[PersonEvent]:
        """Fire every timer due up to `to_ns`, each at its deadline, in order."""
        target = to_ns if self._now is None else max(self._now, to_ns)
        out: list[PersonEvent] = []
        while (deadline := self._next_deadline()) is not None and deadline <= target:
            at = deadline if self._now is None else max(self._now, deadline)
            self._now = at
            self._tracker.limits = self._limits()
            self._drop_tracks(self._tracker.expire(at))
            out += self._evaluate(at, deadline)
        self._now = target
        return out

    def _next_deadline(self) -> int | None:
        """When a person's state may change next without input."""
        due: list[int] = []
        for track in self._persons.values():
            if Sensor.CAMERA in track.seen_by and self._face is not None:
                due.append(self._face.stamp_ns + _ns(self.s.face_timeout_s))
            if track.engagement is Engagement.ENGAGING:
                due.append(track.engagement_since_ns + _ns(self.s.engage_dwell_s) if
                           track.attending else
                           track.attending_since_ns + _ns(self.s.look_away_s))
            elif track.engagement is Engagement.ENGAGED and not track.attending:
                due.append(track.attending_since_ns + _ns(self.s.look_away_s))
            elif track.engagement is Engagement.DISENGAGING:
                due.append(track.attending_since_ns + _ns(self.s.engage_dwell_s)
                           if track.attending else
                           track.engagement_since_ns + _ns(self.s.disengage_hold_s))
            if not track.seen_by:
                due.append(track.lost_since_ns + _ns(self.s.absence_hold_s))
            if not track.real and track.origin is not None:
                due.append(self._clutter_at(track))
        coast = self._tracker.next_deadline()
        if coast is not None:
            due.append(coast)
        if (self._untracked is not None and self._angle_until is not None
                and self._now is not None and self._angle_until > self._now):
            due.append(self._angle_until)
        return min(due, default=None)

    def _angle_radars(self, at: int) -> bool:
        return self._angle_until is not None and at < self._angle_until

    def _face_fresh(self, at: int) -> bool:
        return self._face is not None and at < self._face.stamp_ns + _ns(self.s.face_timeout_s)

    def _untracked_seen(self, at: int) -> Sensor:
        """What shows the untracked person (whether or not they are present yet)."""
        seen = Sensor.NONE
        if (self._radar is not None and self._radar.in_range and not self._angle_radars(at)
                and not self._range_clutter):
            seen |= Sensor.RADAR
        if self._face_holder is None and self._face_fresh(at):
            seen |= Sensor.CAMERA
        return seen

    def _seen_by(self, track: _Track, at: int) -> Sensor:
        if track.track_id is None:
            return self._untracked_seen(at)
        seen = Sensor.RADAR if self._tracker.alive(track.track_id) else Sensor.NONE
        if self._face_holder == track.id and self._face_fresh(at):
            seen |= Sensor.CAMERA
        return seen

    # -- inputs: radar presence and the face of the untracked person --

    def _sensed(self, stamp: int, distance_m: float | None,
                face: FaceSeen | None) -> list[PersonEvent]:
        """A sample of the untracked person was taken: arrival, distance and zone,
        then the state."""
        assert self._now is not None  # _advance ran
        at = self._now
        seen = self._untracked_seen(at)
        source = Sensor.CAMERA if face is not None else Sensor.RADAR
        # The radar's distance counts only while the camera does not see the face.
        trusted = Sensor.CAMERA if Sensor.CAMERA in seen else Sensor.RADAR
        measured = distance_m if source is trusted and source in seen else None
        out: list[PersonEvent] = []
        track = None if self._untracked is None else self._persons[self._untracked]
        if track is None:
            if measured is None:
                return self._evaluate(at, stamp)
            track = self._arrive(stamp, measured, seen)
            if track is None:
                return self._evaluate(at, stamp)
            self._untracked = track.id
            out.append(Arrived(track.id, stamp, track.person()))
        elif measured is not None:
            out += self._move(track, stamp, measured)
        if face is not None and Sensor.CAMERA in seen:
            track.yaw_rad, track.pitch_rad = face.yaw_rad, face.pitch_rad
        return out + self._evaluate(at, stamp)

    # -- inputs: angle radars and the face on a tracked person --

    def _holder(self, face: FaceSeen) -> int | None:
        """The tracked person this face is on, or None (the untracked person's)."""
        holder = None if self._face_holder is None else self._persons[self._face_holder]
        if holder is not None and holder.bearing_rad is None:
            return holder.id  # their track is lost (standing still?): the camera still has them
        horizontal = face.distance_m * math.cos(face.pitch_rad)
        angle = math.radians(self.s.fusion_angle_deg)
        best: tuple[float, int] | None = None
        for track in self._persons.values():
            if track.bearing_rad is None or track.radar_xy is None:
                continue  # no live track
            widen = 2.0 if track.id == self._face_holder else 1.0
            off = _angle_between(face.yaw_rad, track.bearing_rad)
            near = abs(horizontal - math.hypot(*track.radar_xy))
            if off > angle * widen or near > self.s.fusion_distance_m * widen:
                continue
            if track.id == self._face_holder:
                return track.id
            if best is None or (off, track.id) < best:
                best = (off, track.id)
        return None if best is None else best[1]

    def _face_on(self, track: _Track, face: FaceSeen) -> list[PersonEvent]:
        assert self._now is not None
        out = self._move(track, face.stamp_ns, face.distance_m)
        track.yaw_rad, track.pitch_rad = face.yaw_rad, face.pitch_rad
        return out + self._evaluate(self._now, face.stamp_ns)

    def _tracked(self, stamp: int, started: list[int]) -> list[PersonEvent]:
        """After a report: new tracks continue or make persons, every tracked
        person follows their track, then the state."""
        assert self._now is not None
        at = self._now
        tracks = {t.id: t for t in self._tracker.tracks()}
        out: list[PersonEvent] = []
        spots = self._spots_now(at)
        self._clutter_tracks &= set(tracks)
        freed = []
        for track_id in [i for i in sorted(self._clutter_tracks) if i not in started]:
            t = tracks[track_id]
            if not spots.shown((t.x_m, t.y_m), stamp):  # it left the spot: a person
                self._clutter_tracks.discard(track_id)
                freed.append(track_id)
        started = [*started, *freed]
        for track_id in started:
            t = tracks[track_id]
            if track_id not in self._clutter_tracks and spots.near((t.x_m, t.y_m)) is not None \
                    and self._continued(t.x_m, t.y_m, t.bearing_rad, t.distance_m, at) is None:
                spots.shown((t.x_m, t.y_m), stamp)
                self._clutter_tracks.add(track_id)  # a new track at a spot: clutter
                continue
            person = self._continued(t.x_m, t.y_m, t.bearing_rad, t.distance_m, at)
            if person is not None:
                person.track_id = track_id
                if person.id == self._untracked:
                    self._untracked = None
                    self._face_holder = person.id
                continue
            person = self._arrive(stamp, t.distance_m, Sensor.RADAR, track_id)
            if person is None:
                continue
            person.radar_xy, person.bearing_rad = (t.x_m, t.y_m), t.bearing_rad
            person.yaw_rad, person.pitch_rad = t.bearing_rad, 0.0
            person.origin = (t.x_m, t.y_m)
            person.real = track_id in freed  # moved off a spot: through the room
            out.append(Arrived(person.id, stamp, person.person()))
        for person in [self._persons[i] for i in sorted(self._persons)]:
            now = tracks.get(person.track_id) if person.track_id is not None else None
            if now is None:
                continue
            person.radar_xy, person.bearing_rad = (now.x_m, now.y_m), now.bearing_rad
            person.radar_last_ns = now.last_ns
            self._moved(person, (now.x_m, now.y_m))
            if Sensor.CAMERA in self._seen_by(person, at):
                continue
            out += self._move(person, stamp, now.distance_m)
            person.yaw_rad = now.bearing_rad
            person.pitch_rad = 0.0 if person.pitch_rad is None else person.pitch_rad
        return out + self._evaluate(at, stamp)

    def _continued(self, x: float, y: float, bearing: float, distance: float,
                   at: int) -> _Track | None:
        """The person a new track continues: one who lost their track less than
        `absence_hold_s` ago and was last within twice the gate, else the untracked
        person if the face they hold lies at the track's bearing and distance."""
        best: tuple[float, int] | None = None
        for person in self._persons.values():
            if person.track_id is None or self._tracker.alive(person.track_id):
                continue
            assert person.radar_xy is not None
            d = math.hypot(x - person.radar_xy[0], y - person.radar_xy[1])
            if d <= 2.0 * self.s.track_gate_m and (best is None or (d, person.id) < best):
                best = (d, person.id)
        if best is not None:
            return self._persons[best[1]]
        if self._untracked is None or self._face is None or self._face_holder is not None:
            return None
        untracked = self._persons[self._untracked]
        if Sensor.CAMERA not in self._untracked_seen(at):
            return None
        face = self._face
        off = _angle_between(face.yaw_rad, bearing)
        near = abs(face.distance_m * math.cos(face.pitch_rad) - distance)
        if off <= math.radians(self.s.fusion_angle_deg) and near <= self.s.fusion_distance_m:
            return untracked
        return None

    def _drop_tracks(self, dropped: list[int]) -> None:
        if not dropped:
            return
        gone = set(dropped)
        for person in self._persons.values():
            if person.track_id in gone:
                person.bearing_rad = None

    def _arrive(self, stamp: int, distance_m: float, seen: Sensor,
                track_id: int | None = None) -> _Track | None:
        if len(self._persons) >= MAX_PEOPLE:
            self.refused += 1
            return None
        self._last_id += 1
        track = _Track(
            id=self._last_id, arrived_ns=stamp, distance_m=distance_m,
            zone=zone_of(distance_m, self.s), zone_since_ns=stamp, seen_by=seen,
            lost_since_ns=stamp, engagement=Engagement.NONE, engagement_since_ns=stamp,
            attending=False, attending_since_ns=stamp, yaw_rad=None, pitch_rad=None,
            track_id=track_id)
        self._persons[track.id] = track
        return track

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
        """Bring every present person's sensors, presence and engagement up to time
        `at`, by id; changes are stamped `stamp`, or a hold's end if that is later."""
        out: list[PersonEvent] = []
        for person_id in sorted(self._persons):
            out += self._evaluate_one(self._persons[person_id], at, stamp)
        return out

    def _evaluate_one(self, track: _Track, at: int, stamp: int) -> list[PersonEvent]:
        seen = self._seen_by(track, at)
        if Sensor.CAMERA in seen:
            track.real = True
        if self._is_clutter(track, seen, at):
            return self._to_clutter(track, max(stamp, self._clutter_at(track)))
        if seen != track.seen_by:
            if not seen:
                track.lost_since_ns = self._last_shown(track, stamp)
            track.seen_by = seen
        if not seen:
            gone_at = track.lost_since_ns + _ns(self.s.absence_hold_s)
            if at >= gone_at:
                return self._leave(track, max(stamp, gone_at))
        return self._engage(track, at, stamp)

    def _clutter_at(self, track: _Track) -> int:
        return track.arrived_ns + _ns(self.s.clutter_after_s)

    def _is_clutter(self, track: _Track, seen: Sensor, at: int) -> bool:
        """Shown only by the radar, never moved through the room, for the clutter time."""
        return (not track.real and track.origin is not None and seen == Sensor.RADAR
                and at >= self._clutter_at(track))

    def _to_clutter(self, track: _Track, stamp: int) -> list[PersonEvent]:
        """Not a person: their place becomes a spot, and they leave."""
        assert track.origin is not None
        self.clutter += 1
        if track.track_id is None:
            self._range_spots.add(track.origin, stamp)
            self._range_clutter = True
        else:
            self._spots.add(track.origin, stamp)
            self._clutter_tracks.add(track.track_id)
        return self._leave(track, stamp)

    def _last_shown(self, track: _Track, stamp: int) -> int:
        """When the sensors that showed `track` until now last showed them (never
        after `stamp`): the absence hold counts from there, so a sensor's own
        delay in saying "gone" (radar presence's hold, whose OUT_OF_RANGE carries
        the absence's first frame; the face timeout; a track's coast) overlaps
        the hold instead of adding to it."""
        shown: list[int] = []
        if self._face is not None and self._face_owner() is track:
            shown.append(self._face.stamp_ns)
        if track.track_id is not None:
            if track.radar_last_ns is not None:
                shown.append(track.radar_last_ns)
        elif self._radar_lost_ns is not None and self._radar_lost_ns >= track.arrived_ns:
            shown.append(self._radar_lost_ns)
        return min(stamp, max(shown, default=stamp))

    def _engage(self, track: _Track, at: int, stamp: int) -> list[PersonEvent]:
        """The engagement machine (docs/people.md): each way has a hold, so a face
        missed for a moment or a glance back changes nothing."""
        attending = Sensor.CAMERA in track.seen_by and track.zone <= Zone.SOCIAL
        if attending != track.attending:
            track.attending, track.attending_since_ns = attending, stamp
        out: list[PersonEvent] = []
        while True:
            was, since = track.engagement, track.engagement_since_ns
            new, when = was, stamp
            back = track.attending_since_ns + _ns(self.s.engage_dwell_s)
            away = track.attending_since_ns + _ns(self.s.look_away_s)
            if was is Engagement.NONE and attending:
                new = Engagement.ENGAGING
            elif was is Engagement.ENGAGING:
                dwelt = since + _ns(self.s.engage_dwell_s)
                if not attending and at >= away:
                    new, when = Engagement.NONE, max(stamp, away)
                elif attending and at >= dwelt:
                    new, when = Engagement.ENGAGED, max(stamp, dwelt)
            elif was is Engagement.ENGAGED and not attending and at >= away:
                new, when = Engagement.DISENGAGING, max(stamp, away)
            elif was is Engagement.DISENGAGING:
                held = since + _ns(self.s.disengage_hold_s)
                if attending and at >= back:
                    new, when = Engagement.ENGAGED, max(stamp, back)
                elif not attending and at >= held:
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
        del self._persons[track.id]
        if self._untracked == track.id:
            self._untracked = None
        if self._face_holder == track.id:
            self._face_holder = None
        return out
