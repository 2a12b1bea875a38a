"""`bot.eyes`: expressions and gaze, through the eyes driver's arbiter under a lease.

The eyes driver is the one publisher of `eyes/expression` and `eyes/control`;
a program asks it on `eyes/command`, naming a lease that holds `expression`
(for an expression) or `gaze` (for a gaze or the pupils' size). A program
that holds none gets
one implicitly, at app priority: with `for_s`, for that long (the
arbiter ends it on time even if the program dies, and shows the built-in
behaviour's expression again); without, until `bot.eyes.release()` or the bot closes. Once a
lease has ended, the next action takes a new one.

`expression_of()` (names and aliases) and the handle are pure.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Generator
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing
from buddybot.runtime.leasing import check_duration
from buddybot.runtime.node import Node
from buddybot.sdk.actions import ActionLimit, Actuator
from buddybot.sdk.errors import Refused, TimedOut
from buddybot.sdk.leases import Lease, LeaseTable, arbiter_errors
from buddybot.sdk.people import Person

ALIASES: dict[str, m.ExpressionAction] = {
    "awake": m.ExpressionAction.EYE_AWAKE,
    "sleep": m.ExpressionAction.EYE_SLEEP,
    "sleepy": m.ExpressionAction.EYE_SLEEPY,
    "grin": m.ExpressionAction.EYE_GRIN,
    "sad": m.ExpressionAction.EYE_SAD,
    "look_random": m.ExpressionAction.EYE_LOOK_RANDOM,
    "love": m.ExpressionAction.ANIMATE_LOVE,
    "star": m.ExpressionAction.ANIMATE_STAR,
    "alert": m.ExpressionAction.EYE_ALERT,
}
"""Friendly lowercase names of the expressions."""
MAX_DISTANCE_CM = 100000.0


def expression_of(value: m.ExpressionAction | str) -> m.ExpressionAction:
    """The expression `value` names: an `ExpressionAction`, its name
    ("ANIMATE_LOVE") or an alias ("love"); ValueError listing the valid names."""
    if isinstance(value, m.ExpressionAction):
        return value
    if isinstance(value, str):
        if value in ALIASES:
            return ALIASES[value]
        if value in m.ExpressionAction.__members__:
            return m.ExpressionAction[value]
    raise ValueError(f"unknown expression {value!r} (valid: {', '.join(ALIASES)}, or "
                     f"{', '.join(m.ExpressionAction.__members__)})")


def pupil_of(percent: float | None) -> float | None:
    """The pupils' dilation in % (0..100, None: from the distance); ValueError."""
    if percent is None:
        return None
    if isinstance(percent, bool) or not isinstance(percent, int | float) or not (
            math.isfinite(percent) and 0 <= percent <= 100):
        raise ValueError(f"pupil must be a percentage in [0, 100], not {percent!r}")
    return float(percent)


def gaze_of(yaw: float, pitch: float, distance_m: float | None) -> tuple[float, float, float]:
    """(yaw, pitch, target_distance_cm) checked against `EyesCommand`'s ranges;
    ValueError naming the bad value."""
    for name, value, limit in (("yaw", yaw, 3.15), ("pitch", pitch, 1.58)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not (
                math.isfinite(value) and -limit <= value <= limit):
            raise ValueError(f"{name} must be radians in [-{limit}, {limit}], not {value!r}")
    if distance_m is None:
        return float(yaw), float(pitch), 0.0
    if isinstance(distance_m, bool) or not isinstance(distance_m, int | float) or not (
            math.isfinite(distance_m) and 0 <= distance_m * 100 <= MAX_DISTANCE_CM):
        raise ValueError(f"distance_m must be metres in [0, {MAX_DISTANCE_CM / 100:g}] "
                         f"or None, not {distance_m!r}")
    return float(yaw), float(pitch), float(distance_m) * 100


RESOURCES: tuple[str, ...] = ("expression", "gaze")
"""The parts of the eyes a lease holds, and `release` gives back."""


class EyesHandle:
    """One expression or gaze on the eyes: `done`, `wait()`, `cancel()`, `await`.

    Done when the lease it runs under ends (an implicit `for_s` lease expires,
    `bot.eyes.release()`, preemption), or, under a lease of yours, after
    `for_s` when given (the eyes then keep showing it until you change them).
    `wait()` returns why: the lease's end reason, "elapsed" or "canceled".
    It holds no thread and no callback: it reads its lease and a deadline."""

    def __init__(self, what: str, lease: Lease, implicit: bool, for_s: float | None) -> None:
        self.what = what
        self.lease = lease
        self.implicit = implicit
        self._deadline = (None if for_s is None or implicit
                          else time.monotonic() + for_s)
        self._canceled = False

    @property
    def reason(self) -> str | None:
        """Why it is over (None while showing)."""
        if self._canceled:
            return "canceled"
        if not self.lease.active:
            return self.lease.ended or "ended"
        if self._deadline is not None and time.monotonic() >= self._deadline:
            return "elapsed"
        return None

    @property
    def done(self) -> bool:
        return self.reason is not None

    def wait(self, timeout: float | None = None) -> str:
        """Why it is over, once it is; TimedOut after `timeout` s (None: no limit)."""
        end = None if timeout is None else time.monotonic() + timeout
        while (reason := self.reason) is None:
            bounds = [t - time.monotonic() for t in (end, self._deadline) if t is not None]
            if end is not None and time.monotonic() >= end:
                raise TimedOut(f"eyes: {self.what} still showing after {timeout:g} s")
            self.lease.wait_end(max(0.0, min(bounds)) if bounds else None)
        return reason

    def cancel(self, timeout: float | None = None) -> str:
        """Stop it: an implicit lease is released (the built-in behaviour's
        eyes come back); under a lease of yours the handle is only marked done."""
        if self.implicit and self.lease.active:
            self.lease.release(timeout)
        if self.reason is None:
            self._canceled = True
            self.lease.wake()
        return self.reason or "canceled"

    def __await__(self) -> Generator[Any, None, str]:
        return asyncio.to_thread(self.wait).__await__()

    def __repr__(self) -> str:
        reason = self.reason
        return f"EyesHandle({self.what}, {self.lease.lease_id}, " + (
            f"done: {reason})" if reason else "showing)")


class Eyes(Actuator):
    """Expressions and gaze sent to the eyes driver on `eyes/command` (one token
    of the action limit each; `_lock`: one action at a time picks or takes
    its lease)."""

    def __init__(self, node: Node, leases: LeaseTable, timeout: float,
                 limit: ActionLimit | None = None) -> None:
        super().__init__(node, leases, timeout, limit)
        self._implicit: dict[str, Lease] = {}
        """The leases the eyes took themselves, by resource."""

    def express(self, expression: m.ExpressionAction | str, for_s: float | None = None
                ) -> EyesHandle:
        """Show `expression` (see `expression_of`); for `for_s` s under an implicit lease."""
        action = expression_of(expression)
        duration = check_duration(for_s)
        self._take("express")
        return self._command("expression", action.name, duration, expression=action)

    def look_at(self, yaw: float | Person, pitch: float | None = None,
                distance_m: float | None = None, pupil: float | None = None) -> EyesHandle:
        """Turn the gaze to (`yaw`, `pitch`) radians (+ = left, + = up), or to a
        `Person` (their direction and distance); Refused for a person whose
        direction is not known yet. `pupil`: dilation in % instead of the one
        the distance gives (the eyes driver's curve: near -> large)."""
        if isinstance(yaw, Person):
            person = yaw
            if person.yaw_rad is None or person.pitch_rad is None:
                raise Refused(f"person {person.id} has no direction yet (seen by "
                              f"{person.seen_by or 'nothing'}); the camera gives one")
            yaw, pitch, distance_m = person.yaw_rad, person.pitch_rad, person.distance_m
        if pitch is None:
            raise ValueError("look_at(yaw, pitch) needs a pitch (or pass a Person)")
        gaze = gaze_of(yaw, pitch, distance_m)
        size = pupil_of(pupil)
        self._take("look_at")
        return self._command("gaze", f"gaze {gaze[0]:+.2f}/{gaze[1]:+.2f} rad", None,
                             yaw=gaze[0], pitch=gaze[1], target_distance_cm=gaze[2],
                             pupil_percent=size)

    def pupils(self, percent: float) -> EyesHandle:
        """Set the pupils' dilation (0..100 %) where the eyes look now, until the
        next gaze: wide for delight or someone close, small for doubt. Takes the
        gaze, as `look_at` does."""
        size = pupil_of(percent)
        if size is None:
            raise ValueError("pupils(percent) needs a percentage")
        self._take("pupils")
        return self._command("gaze", f"pupils {size:g} %", None, pupil_percent=size)

    def release(self, *what: str, timeout: float | None = None) -> None:
        """End the leases the eyes took themselves for `what` ("expression",
        "gaze"; both when none): the robot's behaviour resumes that part at once,
        e.g. its gaze while the app keeps showing its expression."""
        parts = set(what or RESOURCES)
        unknown = sorted(parts - set(RESOURCES))
        if unknown:
            raise ValueError(f"unknown part(s) {', '.join(unknown)} of the eyes "
                             f"(known: {', '.join(RESOURCES)})")
        with self._lock:
            taken = [self._implicit.pop(r) for r in sorted(parts) if r in self._implicit]
        for lease in taken:
            lease.release(timeout)

    def _lease_for(self, resource: str, for_s: float | None) -> tuple[Lease, bool]:
        """(the lease to command under, whether the eyes took it). A lease of the
        program's own is used as it is; one the eyes took is kept when it fits
        the call (held until released, and no `for_s`), else replaced."""
        held = self.leases.holding(resource)
        own = self._implicit.get(resource)
        if held is not None and held is not own:
            return held, False
        if own is not None and own.active and own.duration_s is None and for_s is None:
            return own, True
        if own is not None:
            own.release()
        lease = self.leases.acquire([resource], "app", for_s, counted=False)
        self._implicit[resource] = lease
        return lease, True

    def _command(self, resource: str, what: str, for_s: float | None, **fields: Any
                 ) -> EyesHandle:
        with self._lock:
            lease, implicit = self._lease_for(resource, for_s)
        with arbiter_errors(keys.EYES_COMMAND, self.timeout):
            leasing.eyes_command(self.node, m.EyesCommand(lease_id=lease.handle, **fields),
                                 self.timeout)
        return EyesHandle(what, lease, implicit, for_s)
