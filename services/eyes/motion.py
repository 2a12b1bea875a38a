"""The eyes' own motion, decided once for the whole face (pure: no I/O, no clock).

Timers of its own in every page would make a left-eye screen and a
right-eye screen blink at different moments and wander apart. So one
`MotionScheduler` per renderer decides blinks, small fixational saccades,
idle glances and `EYE_LOOK_RANDOM` glances, as timed events
(`MotionEvent`: kind, start on the server clock in ms since the epoch,
duration, parameters) that every page draws at the same server time.

The caller owns time and chance: every method takes `now_ms` (the server
clock) and the random generator is injected, so the same calls with the
same seed give the same events (the tests rely on it). An event starts
`lead_ms` after it is decided, so it reaches every page before it begins.

It models human figures, each next to its constant below: saccade
durations from the main sequence; spontaneous, gaze-evoked and drowsy
blinks (none asleep); fixational saccades, smaller while following
someone; glances. Saccade events carry an *offset* added to the commanded
direction and name where they start and end, so a page that missed
earlier events still draws the same motion. The figures and why:
docs/eyes.md, 'Eye renderer'.
"""

from __future__ import annotations

import math
import random
from collections import deque
from dataclasses import dataclass

import msgspec

AWAKE, SLEEP, SLEEPY, LOOK_RANDOM = 0, 1, 2, 5
"""The `ExpressionAction` values the motion depends on (contract/messages.py)."""

NEVER = math.inf

# --- the human figures ------------------------------------------------------------------

MAIN_SEQUENCE_MS_PER_DEG = 2.2
MAIN_SEQUENCE_INTERCEPT_MS = 21.0
SACCADE_MIN_MS = 20.0
SACCADE_MAX_MS = 200.0


def saccade_duration_ms(amplitude_deg: float) -> float:
    """How long a saccade of `amplitude_deg` takes: the main sequence.

    Saccade duration grows about linearly with amplitude: the classic fit
    (Carpenter, "Movements of the Eyes", 1988; Baloh et al., Neurology 1975)
    is ~2.2 ms per degree plus ~21 ms, i.e. ~20-30 ms for the small (< 2 deg)
    fixational ones, ~65 ms at 20 deg and ~200 ms for the largest
    (~80 deg) a person makes without moving the head. Clamped to 20..200 ms.
    """
    duration = MAIN_SEQUENCE_INTERCEPT_MS + MAIN_SEQUENCE_MS_PER_DEG * abs(amplitude_deg)
    return min(SACCADE_MAX_MS, max(SACCADE_MIN_MS, duration))


BLINK_CLOSE_MS = 60.0
"""Closing a blink: fast, ~50-70 ms (lid down-phase of a spontaneous blink)."""
BLINK_OPEN_MS = 160.0
"""Reopening: about 2-3 times slower than closing."""
DROWSY_BLINK_SLOWDOWN = 2.2
"""Drowsy blinks last about twice as long (slow eyelid closure is the classic
sign of sleepiness); EYE_SLEEPY uses this factor on both phases."""
BLINK_REFRACTORY_MS = 600.0
"""No gaze-evoked blink starts within this long of the previous blink (one
right after another would look like a twitch)."""
GAZE_WINDOW_MS = 300.0
"""A commanded change counts as one gaze shift when it happens within this
long (a jump, or a fast turn); a slow pursuit of the same size does not."""
IDLE_AFTER_MS = 1500.0
"""No commanded direction for this long: nobody is being followed (idle)."""
FIXATION_INTERVAL_MS = (600.0, 2200.0)
"""Fixational saccades every 0.6-2.2 s (people make 1-3 per second; these are
the visible ones)."""
FIXATION_IDLE_DEG = (3.0, 2.0)
"""Fixational offsets (yaw, pitch) at most, idle: visible but small."""
FIXATION_ENGAGED_DEG = (1.0, 0.7)
"""... and while following someone: the gaze stays on them."""
IDLE_GLANCE_INTERVAL_MS = (4000.0, 10000.0)
"""An idle glance aside every 4-10 s."""
IDLE_GLANCE_DEG = (6.0, 12.0)
"""Idle glances are modest (below the gaze-blink threshold)."""
HOLD_MS = (600.0, 1500.0)
"""How long a glance holds before looking back."""
LOOK_RANDOM_PAUSE_MS = (400.0, 1200.0)
"""EYE_LOOK_RANDOM: time back at the middle before the next glance."""
LOOK_RANDOM_REACH = (0.7, 0.5)
"""EYE_LOOK_RANDOM glances reach this fraction of max yaw / max pitch."""
LOOK_RANDOM_MIN_DEG = 8.0
"""A glance smaller than this would read as jitter, not as looking somewhere."""


@dataclass(frozen=True)
class MotionConfig:
    """The knobs (from `[eye_renderer]`; defaults here are the shipped ones)."""

    blink_interval_min_ms: float = 2500.0
    blink_interval_max_ms: float = 6500.0
    gaze_blink_deg: float = 18.0
    lead_ms: float = 60.0
    max_yaw_deg: float = 40.0
    max_pitch_deg: float = 30.0


class MotionEvent(msgspec.Struct, kw_only=True):
    """One timed motion every page draws: `kind` "blink" or "saccade", its start
    on the server clock (ms since the epoch), its duration and parameters.

    blink: `close_ms`, `open_ms` (sum = duration), `cause` (spontaneous,
    gaze, drowsy). saccade: `from_yaw`, `from_pitch` -> `yaw`, `pitch`
    (degrees of offset from the commanded direction), `amplitude_deg`,
    `purpose` (fixation, glance, return, rest).
    """

    kind: str
    start_ms: float
    duration_ms: float
    params: dict[str, float | str]

    @property
    def end_ms(self) -> float:
        return self.start_ms + self.duration_ms


@dataclass
class _Glance:
    """A glance under way: it looks back to `back` at `return_ms`."""

    return_ms: float
    back: tuple[float, float]


class MotionScheduler:
    """Decides the face's blinks and saccades; see the module docstring.

    Feed it the expression (`set_expression`) and the commanded direction
    (`set_direction`), call `tick` at `next_due_ms()` (earlier is harmless);
    each returns the events decided, which start `lead_ms` later.
    """

    def __init__(self, config: MotionConfig, rng: random.Random, now_ms: float,
                 expression: int = AWAKE) -> None:
        self.config = config
        self._rng = rng
        self.expression = expression
        self.offset = (0.0, 0.0)            # where the last saccade ends
        self._glance: _Glance | None = None
        self._last_blink_ms = -NEVER        # start of the last blink
        self._last_direction_ms = -NEVER
        self._recent: deque[tuple[float, float, float]] = deque()  # (t, yaw, pitch)
        self._next_blink = NEVER
        self._next_fixation = NEVER
        self._next_glance = NEVER
        self._plan_awake(now_ms)

    # --- inputs ------------------------------------------------------------------------

    def configure(self, config: MotionConfig, now_ms: float) -> None:
        """A live settings change: new bounds apply from the next blink drawn."""
        changed = (config.blink_interval_min_ms, config.blink_interval_max_ms) != (
            self.config.blink_interval_min_ms, self.config.blink_interval_max_ms)
        self.config = config
        if changed and self.expression != SLEEP:
            self._next_blink = now_ms + self._blink_interval()

    def set_expression(self, action: int, now_ms: float) -> list[MotionEvent]:
        """A new expression: asleep stops everything (after one saccade back to
        rest as the lids close); waking replans; leaving EYE_LOOK_RANDOM looks
        back now."""
        before, self.expression = self.expression, int(action)
        events: list[MotionEvent] = []
        if self.expression == before:
            return self.tick(now_ms)
        if self.expression == SLEEP:
            self._glance = None
            self._next_blink = self._next_fixation = self._next_glance = NEVER
            if self.offset != (0.0, 0.0):
                events.append(self._saccade(0.0, 0.0, now_ms, "rest"))
            return events
        if before == SLEEP:
            self._plan_awake(now_ms)
        elif before == LOOK_RANDOM and self._glance is not None:
            events += self._look_back(now_ms)
        if self.expression == LOOK_RANDOM and self._glance is None:
            self._next_glance = now_ms          # start looking around at once
        elif before == LOOK_RANDOM:
            self._next_glance = now_ms + self._uniform(IDLE_GLANCE_INTERVAL_MS)
        return events + self.tick(now_ms)

    def set_direction(self, yaw: float, pitch: float, now_ms: float) -> list[MotionEvent]:
        """A commanded direction (degrees): a large shift brings a blink; someone
        being followed ends an idle glance."""
        was_idle = self._idle(now_ms)
        # Compared with the samples of the last GAZE_WINDOW_MS and always the
        # previous one (a jump after a quiet spell is a shift too).
        while len(self._recent) > 1 and now_ms - self._recent[0][0] > GAZE_WINDOW_MS:
            self._recent.popleft()
        shift = max((math.hypot(yaw - y, pitch - p) for _t, y, p in self._recent),
                    default=0.0)
        self._recent.append((now_ms, yaw, pitch))
        self._last_direction_ms = now_ms
        events: list[MotionEvent] = []
        if self.expression == SLEEP:
            return events
        if shift >= self.config.gaze_blink_deg:
            self._recent.clear()
            self._recent.append((now_ms, yaw, pitch))
            events += self._blink(now_ms, "gaze")
        if was_idle and self._glance is not None and self.expression != LOOK_RANDOM:
            events += self._look_back(now_ms)
        return events + self.tick(now_ms)

    # --- time --------------------------------------------------------------------------

    def next_due_ms(self) -> float:
        """When `tick` next has something to decide (inf: nothing, e.g. asleep)."""
        glance = self._glance.return_ms if self._glance is not None else NEVER
        return min(self._next_blink, self._next_fixation, self._next_glance, glance)

    def tick(self, now_ms: float) -> list[MotionEvent]:
        """Decide everything due by `now_ms` (each once, replanned from now)."""
        events: list[MotionEvent] = []
        if self.expression == SLEEP:
            return events
        if self._next_blink <= now_ms:
            events += self._blink(now_ms, "spontaneous")
        if self._glance is not None and self._glance.return_ms <= now_ms:
            events += self._look_back(now_ms)
        elif self._glance is None and self._next_glance <= now_ms:
            if self.expression == LOOK_RANDOM:
                events += self._start_glance(now_ms, self._look_random_target())
            elif self._idle(now_ms):
                events += self._start_glance(now_ms, self._idle_glance_target())
            else:
                self._next_glance = now_ms + self._uniform(IDLE_GLANCE_INTERVAL_MS)
        if self._next_fixation <= now_ms:
            if self._glance is None:
                events.append(self._fixation(now_ms))
            self._next_fixation = now_ms + self._uniform(FIXATION_INTERVAL_MS)
        return events

    # --- decisions ---------------------------------------------------------------------

    def _plan_awake(self, now_ms: float) -> None:
        if self.expression == SLEEP:
            return
        self._next_blink = now_ms + self._blink_interval()
        self._next_fixation = now_ms + self._uniform(FIXATION_INTERVAL_MS)
        self._next_glance = now_ms + (0.0 if self.expression == LOOK_RANDOM
                                      else self._uniform(IDLE_GLANCE_INTERVAL_MS))

    def _idle(self, now_ms: float) -> bool:
        return now_ms - self._last_direction_ms >= IDLE_AFTER_MS

    def _blink(self, now_ms: float, cause: str) -> list[MotionEvent]:
        """A blink starting `lead_ms` from now (a gaze-evoked one not right after
        another); the next spontaneous one is planned from it either way."""
        self._next_blink = now_ms + self._blink_interval()
        if cause == "gaze" and now_ms - self._last_blink_ms < BLINK_REFRACTORY_MS:
            return []
        self._last_blink_ms = now_ms
        slow = DROWSY_BLINK_SLOWDOWN if self.expression == SLEEPY else 1.0
        close, open_ = BLINK_CLOSE_MS * slow, BLINK_OPEN_MS * slow
        if slow != 1.0 and cause == "spontaneous":
            cause = "drowsy"
        return [MotionEvent(kind="blink", start_ms=now_ms + self.config.lead_ms,
                            duration_ms=close + open_,
                            params={"close_ms": close, "open_ms": open_, "cause": cause})]

    def _saccade(self, yaw: float, pitch: float, now_ms: float, purpose: str) -> MotionEvent:
        from_yaw, from_pitch = self.offset
        amplitude = math.hypot(yaw - from_yaw, pitch - from_pitch)
        self.offset = (yaw, pitch)
        return MotionEvent(kind="saccade", start_ms=now_ms + self.config.lead_ms,
                           duration_ms=saccade_duration_ms(amplitude),
                           params={"from_yaw": from_yaw, "from_pitch": from_pitch,
                                   "yaw": yaw, "pitch": pitch,
                                   "amplitude_deg": amplitude, "purpose": purpose})

    def _fixation(self, now_ms: float) -> MotionEvent:
        reach = FIXATION_IDLE_DEG if self._idle(now_ms) else FIXATION_ENGAGED_DEG
        return self._saccade(self._rng.uniform(-reach[0], reach[0]),
                             self._rng.uniform(-reach[1], reach[1]), now_ms, "fixation")

    def _start_glance(self, now_ms: float, target: tuple[float, float]) -> list[MotionEvent]:
        back = self.offset
        event = self._saccade(target[0], target[1], now_ms, "glance")
        hold = self._uniform(HOLD_MS)
        # Look back once the look is over and held: times are decision times,
        # so the return starts `duration + hold` after the look starts.
        self._glance = _Glance(return_ms=now_ms + event.duration_ms + hold, back=back)
        self._next_glance = NEVER
        events = [event]
        if float(event.params["amplitude_deg"]) >= self.config.gaze_blink_deg:
            events = self._blink(now_ms, "gaze") + events
        return events

    def _look_back(self, now_ms: float) -> list[MotionEvent]:
        glance, self._glance = self._glance, None
        back = (0.0, 0.0) if glance is None else glance.back
        event = self._saccade(back[0], back[1], now_ms, "return")
        if self.expression == LOOK_RANDOM:
            self._next_glance = now_ms + event.duration_ms + self._uniform(LOOK_RANDOM_PAUSE_MS)
        else:
            self._next_glance = now_ms + self._uniform(IDLE_GLANCE_INTERVAL_MS)
        self._next_fixation = now_ms + event.duration_ms + self._uniform(FIXATION_INTERVAL_MS)
        events = [event]
        if float(event.params["amplitude_deg"]) >= self.config.gaze_blink_deg:
            events = self._blink(now_ms, "gaze") + events
        return events

    def _look_random_target(self) -> tuple[float, float]:
        """Somewhere in the room: up to 70 % of the yaw reach, 50 % of the pitch,
        far enough from the middle to read as looking, not jitter."""
        ry = LOOK_RANDOM_REACH[0] * self.config.max_yaw_deg
        rp = LOOK_RANDOM_REACH[1] * self.config.max_pitch_deg
        least = min(LOOK_RANDOM_MIN_DEG, 0.9 * ry)
        for _ in range(20):
            yaw, pitch = self._rng.uniform(-ry, ry), self._rng.uniform(-rp, rp)
            if math.hypot(yaw, pitch) >= least:
                break
        return yaw, pitch

    def _idle_glance_target(self) -> tuple[float, float]:
        angle = self._rng.uniform(0.0, 2.0 * math.pi)
        size = self._uniform(IDLE_GLANCE_DEG)
        return size * math.cos(angle), 0.6 * size * math.sin(angle)

    def _blink_interval(self) -> float:
        lo = self.config.blink_interval_min_ms
        return self._rng.uniform(lo, max(lo, self.config.blink_interval_max_ms))

    def _uniform(self, bounds: tuple[float, float]) -> float:
        return self._rng.uniform(bounds[0], bounds[1])
