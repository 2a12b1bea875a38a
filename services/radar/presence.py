"""The presence rule: radar reports -> IN_RANGE / OUT_OF_RANGE, with what real radars need.

Pure logic, driven by explicit timestamps (seconds, monotonic), so every
timing rule is tested without waiting.

The base rule: among the sensors whose target_state is not NO_TARGET take
the one with the smallest detection distance; IN_RANGE if it is within
`range_m`; STANDING if that sensor says STATIONARY only, else MOVING;
publish on change. What a real LD2410 adds, and the answer: hysteresis
(`exit_margin_m`), an absence hold, a target-kind hold, stale sensors
excluded and reported, target states 4..6 read as "no target", a bounded
sensor table that a flood of invented ids cannot churn, LD2450 reports
read as the same per-sensor readings (`read_targets`), and verdicts
stamped by the frame that caused them, never the largest stamp seen
(OUT_OF_RANGE: the first frame of the absence, which the hold only
confirms, so a consumer's own hold counts from the same moment).

Rationale: docs/radar.md, '`buddybot run radar-presence`', 'Angle radars
(LD2450) and mixing models' and 'What the network cannot do to it'.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from buddybot.contract import messages as m
from buddybot.contract.messages import PresenceState, PresenceTarget, RadarTarget, TargetState
from buddybot.radar.settings import RadarPresenceSettings
from buddybot.radar.zones import ZoneVerdict, judge
from buddybot.runtime.limits import BoundedDict

ESTABLISHED_S = 1.0  # a sensor heard this long ...
ESTABLISHED_FRAMES = 5  # ... with this many frames is a real one (10 Hz: after ~1 s)


@dataclass(frozen=True)
class Reading:
    """What the rule needs from one sensor frame."""

    target_state: int
    detection_distance_cm: int
    moving_distance_cm: int = 0
    still_distance_cm: int = 0

    @property
    def present(self) -> bool:
        """A moving and/or still target; NO_TARGET and the background-noise
        detection states (4..6) carry none."""
        return self.target_state in m.TARGET_STATES

    @property
    def distance_m(self) -> float:
        """The contract's reading of the frame's distance (`target_distance_cm`)."""
        return m.target_distance_cm(self.target_state, self.detection_distance_cm,
                                    self.moving_distance_cm, self.still_distance_cm) / 100.0

    @property
    def kind(self) -> PresenceTarget:
        """STANDING only when the sensor says STATIONARY alone (the base rule)."""
        return (PresenceTarget.STANDING if self.target_state == TargetState.STATIONARY
                else PresenceTarget.MOVING)


@dataclass(frozen=True)
class TargetsReading:
    """What the rule needs from one angle-radar report, after the zones: the
    nearest counted target (None: nobody counted), and how many were not counted."""

    nearest: RadarTarget | None
    moving: bool = False
    ignored: int = 0
    """Targets inside an ignore zone."""
    outside: int = 0
    """Targets outside every detect zone."""

    @property
    def present(self) -> bool:
        return self.nearest is not None

    @property
    def distance_m(self) -> float:
        return 0.0 if self.nearest is None else self.nearest.distance_m

    @property
    def kind(self) -> PresenceTarget:
        return PresenceTarget.MOVING if self.moving else PresenceTarget.STANDING


SensorReading = Reading | TargetsReading
"""One sensor's latest report, whichever the model: the table holds both."""


def read_targets(targets: Sequence[RadarTarget], rules: RadarPresenceSettings) -> TargetsReading:
    """An LD2450 report as a reading: the targets the zones count, the nearest of
    them (by its horizontal distance from the camera) decides distance and kind.

    The nearest, as for LD2410 sensors: the verdict describes the person
    closest to the robot. Its kind comes from its speed, MOVING when
    |speed| > `moving_speed_mps` (0.1 m/s): a person standing reads about 0
    (a few cm/s while fidgeting), a slow walk ~0.5 m/s, so 0.1 splits them
    with room on both sides; `target_hold_s` then smooths a fidget that
    crosses it. The speed is radial (Doppler, toward or away from the
    sensor): someone walking straight across its view reads slow and may be
    STANDING until their path bends.
    """
    nearest: RadarTarget | None = None
    ignored = outside = 0
    for target in targets:
        verdict = judge(rules.zones, target.position.x, target.position.y)
        if verdict is ZoneVerdict.IGNORED:
            ignored += 1
        elif verdict is ZoneVerdict.OUTSIDE:
            outside += 1
        elif nearest is None or target.distance_m < nearest.distance_m:
            nearest = target
    moving = nearest is not None and abs(nearest.speed_mps) > rules.moving_speed_mps
    return TargetsReading(nearest, moving, ignored, outside)


@dataclass(frozen=True)
class Verdict:
    """A presence change to publish; `stamp_ns` of the frame that caused it."""

    presence: PresenceState
    target: PresenceTarget
    distance_m: float
    stamp_ns: int


@dataclass
class _Sensor:
    reading: SensorReading
    seen_s: float
    stamp_ns: int
    first_s: float
    frames: int = 1

    @property
    def established(self) -> bool:
        return self.frames >= ESTABLISHED_FRAMES and self.seen_s - self.first_s >= ESTABLISHED_S


@dataclass
class PresenceTracker:
    """Feed frames with `update()` and call `tick()` periodically (for holds and staleness).

    Both return a Verdict when the published state changes, else None.

    The state starts *unknown* (None), not OUT_OF_RANGE: a
    presence service that restarts while the robot believes someone is
    there must say OUT_OF_RANGE once nobody is seen, or the latched IN_RANGE
    of its previous life would stand forever. So the first verdict is
    IN_RANGE with the first frame in range, or OUT_OF_RANGE after
    `absence_hold_s` of fresh data with nobody in range.
    """

    rules: RadarPresenceSettings = field(default_factory=RadarPresenceSettings)
    """The rule's tuning is the `[radar_presence]` table itself: its defaults and
    ranges (checked when a config or an option is read) live in settings.py, the
    reasons for each default in docs/radar.md."""
    presence: PresenceState | None = None
    target: PresenceTarget = PresenceTarget.MOVING
    _sensors: BoundedDict[str, _Sensor] = field(init=False)
    _absent_since: float | None = None
    _absent_stamp: int = 0
    """The stamp of the first frame of the absence (OUT_OF_RANGE's stamp)."""
    _pending_target: PresenceTarget | None = None
    _pending_since: float = 0.0
    _last_stamp: int = 0
    _distance_m: float = 0.0

    def __post_init__(self) -> None:
        self._sensors = BoundedDict(self.rules.max_sensors)
        self._evicted = 0

    @property
    def evicted(self) -> int:
        """Sensors forgotten to keep the table within `max_sensors`."""
        return self._evicted + self._sensors.evicted

    def established(self, sensor: str) -> bool:
        """Whether `sensor` has been reporting steadily (see ESTABLISHED_S)."""
        entry = self._sensors.get(sensor)
        return entry is not None and entry.established

    # -- inputs --

    def update(self, sensor: str, reading: SensorReading, now_s: float,
               stamp_ns: int) -> Verdict | None:
        """A report from `sensor` (any stable name, e.g. "0/1" = device/radar),
        of either model: a sensor that changes model keeps its entry."""
        entry = self._sensors.get(sensor)
        if entry is None:
            self._make_room()
            self._sensors[sensor] = _Sensor(reading, now_s, stamp_ns, first_s=now_s)
        else:
            entry.reading, entry.seen_s, entry.stamp_ns = reading, now_s, stamp_ns
            entry.frames += 1
            self._sensors.touch(sensor)
        self._last_stamp = stamp_ns  # the latest frame's, never the largest seen
        return self._evaluate(now_s, stamp_ns)

    def _make_room(self) -> None:
        """Before a new sensor: forget the not established one with the fewest
        frames, the most recently heard of those (if all are established: the
        least recently heard)."""
        if len(self._sensors) < self._sensors.max_items:
            return
        entries = self._sensors.items()  # least recently heard first
        candidates = [(s.frames, -i, k) for i, (k, s) in enumerate(entries)
                      if not s.established]
        victim = min(candidates)[2] if candidates else entries[0][0]
        self._sensors.pop(victim)
        self._evicted += 1

    def tick(self, now_s: float) -> Verdict | None:
        """Time passes: holds expire, silent sensors go stale, and ids that
        went silent before they were established are forgotten."""
        self._forget_unestablished(now_s)
        return self._evaluate(now_s, self._last_stamp)

    def _forget_unestablished(self, now_s: float) -> None:
        """Once the table has had to evict (a flood of ids), a sensor never
        established that falls silent never proved to be one (the flood's ids
        each send a frame or two): it is forgotten, and counted as evicted,
        rather than reported as a silent sensor for ever. Without a flood
        nothing changes: a sensor dying in its first second is still reported."""
        if self.evicted == 0:
            return
        limit = self.rules.stale_after_s
        gone = [k for k, s in self._sensors.items()
                if not s.established and now_s - s.seen_s > limit]
        for key in gone:
            self._sensors.pop(key)
        self._evicted += len(gone)

    # -- state --

    def stale_sensors(self, now_s: float) -> list[str]:
        limit = self.rules.stale_after_s
        return sorted(k for k, s in self._sensors.items() if now_s - s.seen_s > limit)

    def _any_fresh(self, now_s: float) -> bool:
        limit = self.rules.stale_after_s
        return any(now_s - s.seen_s <= limit for s in self._sensors.values())

    def known_sensors(self) -> list[str]:
        return sorted(self._sensors)

    # -- the rule --

    def _nearest(self, now_s: float) -> tuple[SensorReading, int] | None:
        best: tuple[SensorReading, int] | None = None
        for s in self._sensors.values():
            if now_s - s.seen_s > self.rules.stale_after_s or not s.reading.present:
                continue
            if best is None or s.reading.distance_m < best[0].distance_m:
                best = (s.reading, s.stamp_ns)
        return best

    def _evaluate(self, now_s: float, stamp_ns: int) -> Verdict | None:
        if not self._any_fresh(now_s):
            # Nobody can tell: keep the verdict and restart the absence hold
            # when data returns, rather than inventing "nobody here".
            self._absent_since = None
            return None
        nearest = self._nearest(now_s)
        rules = self.rules
        limit = rules.range_m + (rules.exit_margin_m if self.presence == PresenceState.IN_RANGE
                                 else 0.0)
        within = nearest is not None and nearest[0].distance_m <= limit + 1e-9
        if nearest is not None:
            self._distance_m = nearest[0].distance_m
        if within:
            assert nearest is not None
            reading, stamp = nearest
            self._absent_since = None
            kind = reading.kind
            if self.presence != PresenceState.IN_RANGE:
                self.presence = PresenceState.IN_RANGE
                self.target = kind
                self._pending_target = None
                return self._verdict(stamp)
            return self._track_target(kind, now_s, stamp)
        self._pending_target = None
        if self.presence == PresenceState.OUT_OF_RANGE:
            return None
        if self._absent_since is None:
            self._absent_since, self._absent_stamp = now_s, stamp_ns
        if now_s - self._absent_since >= rules.absence_hold_s:
            self.presence = PresenceState.OUT_OF_RANGE
            self._absent_since = None
            if nearest is None:
                self._distance_m = 0.0
            return self._verdict(self._absent_stamp)
        return None

    def _track_target(self, kind: PresenceTarget, now_s: float, stamp: int) -> Verdict | None:
        if kind == self.target:
            self._pending_target = None
            return None
        if self._pending_target != kind:
            self._pending_target = kind
            self._pending_since = now_s
        if now_s - self._pending_since >= self.rules.target_hold_s:
            self.target = kind
            self._pending_target = None
            return self._verdict(stamp)
        return None

    def _verdict(self, stamp_ns: int) -> Verdict:
        assert self.presence is not None
        return Verdict(self.presence, self.target, round(self._distance_m, 3), stamp_ns)
