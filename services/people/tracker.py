"""Radar tracks from angle-radar reports: ids that survive slot swaps (pure).

An angle radar (LD2450) reports up to three targets per report, each in a
*slot* the sensor may reassign from one report to the next: the slot is no
identity. `Tracker` gives every person a track id that lasts while they
are seen, from the targets' positions alone (the camera's frame, metres,
as `RadarTarget.position` carries them): tracks are predicted to the
report's time, (track, target) pairs within `gate_m` are taken greedily,
nearest first, ties broken by id and coordinates (never by slot), one
track for a person several sensors see, a track dropped after `coast_s`
unmatched, at most `max_tracks`. Time is the reports' stamps and
`expire(now_ns)`; nothing reads a clock.

Rationale and limits: docs/people.md, 'Angle radars: tracks, fusion with the face'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

_NS_PER_S = 1_000_000_000
MAX_SPEED_MPS = 3.0
"""Fastest walk assumed; a larger measured velocity is clipped (a mismatch, not a sprint)."""
_VELOCITY_GAIN = 0.5
"""Weight of a new velocity measurement (the rest is the previous estimate)."""

SensorId = tuple[int, int]
"""(device_id, radar_id) of an angle radar."""


@dataclass(frozen=True, slots=True)
class Target:
    """One target of a report: x forward, y left (metres, camera frame)."""

    x_m: float
    y_m: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.x_m) and math.isfinite(self.y_m)):
            raise ValueError(f"target position must be finite, not ({self.x_m}, {self.y_m})")


@dataclass(frozen=True, slots=True)
class Report:
    """Every target one sensor reported at `stamp_ns` (empty: nobody)."""

    stamp_ns: int
    sensor: SensorId
    targets: tuple[Target, ...]


@dataclass(frozen=True, slots=True)
class TrackerLimits:
    gate_m: float = 0.6
    coast_s: float = 1.0
    max_tracks: int = 8


@dataclass(frozen=True, slots=True)
class Track:
    """A tracked target now (a snapshot)."""

    id: int
    x_m: float
    y_m: float
    first_ns: int
    last_ns: int
    sensors: frozenset[SensorId]
    """Sensors that have reported it."""

    @property
    def bearing_rad(self) -> float:
        """Direction from the camera, + = the robot's left."""
        return math.atan2(self.y_m, self.x_m)

    @property
    def distance_m(self) -> float:
        """Horizontal range from the camera."""
        return math.hypot(self.x_m, self.y_m)


@dataclass
class _State:
    id: int
    x: float
    y: float
    first_ns: int
    last_ns: int
    vx: float = 0.0
    vy: float = 0.0
    seen: dict[SensorId, tuple[int, float, float]] = field(default_factory=dict)
    """Per sensor, its last measurement (stamp, x, y): the velocity's base."""

    def predicted(self, stamp_ns: int, coast_ns: int) -> tuple[float, float]:
        dt = min(max(0, stamp_ns - self.last_ns), coast_ns) / _NS_PER_S
        return self.x + self.vx * dt, self.y + self.vy * dt

    def measure(self, stamp_ns: int, sensor: SensorId, target: Target) -> None:
        before = self.seen.get(sensor)
        if before is not None and stamp_ns > before[0]:
            dt = (stamp_ns - before[0]) / _NS_PER_S
            vx, vy = (target.x_m - before[1]) / dt, (target.y_m - before[2]) / dt
            speed = math.hypot(vx, vy)
            if speed > MAX_SPEED_MPS:
                vx, vy = vx * MAX_SPEED_MPS / speed, vy * MAX_SPEED_MPS / speed
            g = _VELOCITY_GAIN
            self.vx, self.vy = g * vx + (1 - g) * self.vx, g * vy + (1 - g) * self.vy
        self.seen[sensor] = (stamp_ns, target.x_m, target.y_m)
        self.x, self.y = target.x_m, target.y_m
        self.last_ns = max(self.last_ns, stamp_ns)

    def snapshot(self) -> Track:
        return Track(self.id, self.x, self.y, self.first_ns, self.last_ns,
                     frozenset(self.seen))


class Tracker:
    """Tracks of every angle radar together; single-threaded. `limits` may be
    replaced between calls (a live setting)."""

    def __init__(self, limits: TrackerLimits | None = None) -> None:
        self.limits = limits or TrackerLimits()
        self._tracks: dict[int, _State] = {}
        self._last_id = 0
        self.refused = 0
        """Targets that found no track while `max_tracks` existed."""

    def tracks(self) -> tuple[Track, ...]:
        """The live tracks, by id."""
        return tuple(t.snapshot() for _, t in sorted(self._tracks.items()))

    def alive(self, track_id: int) -> bool:
        return track_id in self._tracks

    def next_deadline(self) -> int | None:
        """When the next track is dropped if nothing reports it."""
        coast = _ns(self.limits.coast_s)
        return min((t.last_ns + coast for t in self._tracks.values()), default=None)

    def expire(self, now_ns: int) -> list[int]:
        """Drop the tracks unseen for `coast_s` at `now_ns`; their ids."""
        coast = _ns(self.limits.coast_s)
        gone = sorted(i for i, t in self._tracks.items() if now_ns >= t.last_ns + coast)
        for i in gone:
            del self._tracks[i]
        return gone

    def update(self, report: Report) -> list[int]:
        """Associate one report's targets; the ids of the tracks it started."""
        limits = self.limits
        coast = _ns(limits.coast_s)
        # By position, not slot: a permutation of the report gives the same ids.
        targets = sorted(report.targets, key=lambda t: (t.x_m, t.y_m))
        pairs: list[tuple[float, int, int]] = []
        for track in self._tracks.values():
            px, py = track.predicted(report.stamp_ns, coast)
            for j, target in enumerate(targets):
                d = math.hypot(target.x_m - px, target.y_m - py)
                if d <= limits.gate_m:
                    pairs.append((d, track.id, j))
        pairs.sort()
        used_tracks: set[int] = set()
        used_targets: set[int] = set()
        for _d, track_id, j in pairs:
            if track_id in used_tracks or j in used_targets:
                continue
            used_tracks.add(track_id)
            used_targets.add(j)
            self._tracks[track_id].measure(report.stamp_ns, report.sensor, targets[j])
        started: list[int] = []
        for j, target in enumerate(targets):
            if j in used_targets:
                continue
            if len(self._tracks) >= limits.max_tracks:
                self.refused += 1
                continue
            self._last_id += 1
            track = _State(self._last_id, target.x_m, target.y_m, report.stamp_ns,
                           report.stamp_ns)
            track.seen[report.sensor] = (report.stamp_ns, target.x_m, target.y_m)
            self._tracks[track.id] = track
            started.append(track.id)
        return started


def _ns(seconds: float) -> int:
    return round(seconds * _NS_PER_S)
