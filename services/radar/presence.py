"""The presence rule: radar frames -> IN_RANGE / OUT_OF_RANGE, with what real radars need.

Pure logic, driven by explicit timestamps (seconds, monotonic), so every
timing rule is tested without waiting.

The seed's rule (5.1.4): among the sensors whose target_state is not
NO_TARGET take the one with the smallest detection distance; IN_RANGE if
it is within `range_m`; STANDING if that sensor says STATIONARY only,
else MOVING; publish on change. What a real LD2410 adds, and the answer:

* A person standing near the border makes the distance jitter by tens of
  cm: entering needs `distance <= range_m`, leaving needs every target
  beyond `range_m + exit_margin_m` (hysteresis).
* The sensor drops a present person for a frame or a few (NO_TARGET
  blips, energy dips): OUT_OF_RANGE is only declared once nobody has been
  within the exit range for `absence_hold_s`. Entering needs no hold, so
  the robot reacts within one frame.
* STATIONARY/BOTH flips every few frames while someone fidgets: a new
  target kind is published only once it has lasted `target_hold_s`.
* A sensor that stops sending (unplugged, bridge down) is excluded after
  `stale_after_s` and reported; its last frame is not taken for "nobody
  here" nor for "still here". With no fresh sensor at all the verdict is
  kept (we do not know) and the service reports the outage.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from buddybot.core.messages import PresenceState, PresenceTarget, TargetState


@dataclass(frozen=True)
class PresenceRules:
    """Tuning of the rule; defaults documented in docs/radar.md."""

    range_m: float = 2.0
    exit_margin_m: float = 0.3
    absence_hold_s: float = 3.0
    target_hold_s: float = 1.0
    stale_after_s: float = 1.5

    def __post_init__(self) -> None:
        if self.range_m <= 0:
            raise ValueError(f"range_m must be > 0, got {self.range_m}")
        for name in ("exit_margin_m", "absence_hold_s", "target_hold_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.stale_after_s <= 0:
            raise ValueError(f"stale_after_s must be > 0, got {self.stale_after_s}")


@dataclass(frozen=True)
class Reading:
    """What the rule needs from one sensor frame."""

    target_state: int
    detection_distance_cm: int
    moving_distance_cm: int = 0
    still_distance_cm: int = 0

    @property
    def present(self) -> bool:
        return self.target_state != TargetState.NO_TARGET

    @property
    def distance_m(self) -> float:
        """Detection distance; a sensor that says "target" with detection 0 cm
        (seen on real modules) falls back to the distance of the kind it reports."""
        cm = self.detection_distance_cm
        if cm == 0:
            if self.target_state & TargetState.MOVING:
                cm = self.moving_distance_cm
            else:
                cm = self.still_distance_cm
        return cm / 100.0


@dataclass(frozen=True)
class Verdict:
    """A presence change to publish; `stamp_ns` of the frame that caused it."""

    presence: PresenceState
    target: PresenceTarget
    distance_m: float
    stamp_ns: int


@dataclass
class _Sensor:
    reading: Reading
    seen_s: float
    stamp_ns: int
    stale: bool = False


@dataclass
class PresenceTracker:
    """Feed frames with `update()` and call `tick()` periodically (for holds and staleness).

    Both return a Verdict when the published state changes, else None.

    The state starts *unknown* (None), not OUT_OF_RANGE as in the seed: a
    presence service that restarts while the robot believes someone is
    there must say OUT_OF_RANGE once nobody is seen, or the latched IN_RANGE
    of its previous life would stand forever. So the first verdict is
    IN_RANGE with the first frame in range, or OUT_OF_RANGE after
    `absence_hold_s` of fresh data with nobody in range.
    """

    rules: PresenceRules = field(default_factory=PresenceRules)
    presence: PresenceState | None = None
    target: PresenceTarget = PresenceTarget.MOVING
    _sensors: dict[str, _Sensor] = field(default_factory=dict)
    _absent_since: float | None = None
    _pending_target: PresenceTarget | None = None
    _pending_since: float = 0.0
    _last_stamp: int = 0
    _distance_m: float = 0.0

    # -- inputs --

    def update(self, sensor: str, reading: Reading, now_s: float, stamp_ns: int) -> Verdict | None:
        """A frame from `sensor` (any stable name, e.g. "0/1" = device/radar)."""
        self._sensors[sensor] = _Sensor(reading, now_s, stamp_ns)
        self._last_stamp = max(self._last_stamp, stamp_ns)
        return self._evaluate(now_s, stamp_ns)

    def tick(self, now_s: float) -> Verdict | None:
        """Time passes: holds expire, silent sensors go stale."""
        return self._evaluate(now_s, self._last_stamp)

    # -- state --

    def stale_sensors(self, now_s: float) -> list[str]:
        limit = self.rules.stale_after_s
        return sorted(k for k, s in self._sensors.items() if now_s - s.seen_s > limit)

    def fresh_sensors(self, now_s: float) -> list[str]:
        return sorted(k for k, s in self._sensors.items()
                      if now_s - s.seen_s <= self.rules.stale_after_s)

    def known_sensors(self) -> list[str]:
        return sorted(self._sensors)

    # -- the rule --

    def _nearest(self, now_s: float) -> tuple[Reading, int] | None:
        best: tuple[Reading, int] | None = None
        for s in self._sensors.values():
            if now_s - s.seen_s > self.rules.stale_after_s or not s.reading.present:
                continue
            if best is None or s.reading.distance_m < best[0].distance_m:
                best = (s.reading, s.stamp_ns)
        return best

    def _evaluate(self, now_s: float, stamp_ns: int) -> Verdict | None:
        if not self.fresh_sensors(now_s):
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
            kind = (PresenceTarget.STANDING if reading.target_state == TargetState.STATIONARY
                    else PresenceTarget.MOVING)
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
            self._absent_since = now_s
        if now_s - self._absent_since >= rules.absence_hold_s:
            self.presence = PresenceState.OUT_OF_RANGE
            self._absent_since = None
            if nearest is None:
                self._distance_m = 0.0
            return self._verdict(stamp_ns)
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
