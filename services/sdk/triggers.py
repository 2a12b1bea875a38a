"""Events a program derives from who is present: dwell, distance, approach (pure).

The people service says who is there and how near; what a behaviour asks
next is "present for N s", "within a metre (and not flickering at the
edge)", "walking towards the robot or away". Each trigger here is fed the
persons present at a time (`update(now_ns, persons)`) and returns the
events that became true, each at most once per change, so the robot's
own behaviour and any app answer those questions the same way.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Protocol

from buddybot.sdk.persons import Event, Person

DERIVED: tuple[str, ...] = ("DWELL", "NEAR", "FAR", "APPROACHING", "RECEDING")
"""The kinds of the derived events."""

_NS = 1_000_000_000


class Trigger(Protocol):
    def update(self, now_ns: int, persons: tuple[Person, ...]) -> list[Event]: ...


def _check(name: str, value: float, *, positive: bool = False) -> float:
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        raise ValueError(f"{name} must be a finite number {'>' if positive else '>='} 0, "
                         f"not {value!r}")
    return value


@dataclass
class Dwell:
    """DWELL once per person, `seconds` after their arrival (stamped then): a person
    already there when the trigger starts counts from when they really arrived."""

    seconds: float
    _done: set[int] = field(default_factory=set)

    def __post_init__(self) -> None:
        _check("seconds", self.seconds)

    def update(self, now_ns: int, persons: tuple[Person, ...]) -> list[Event]:
        self._done &= {p.id for p in persons}
        out = []
        for p in persons:
            due = (p.arrived_ns if p.arrived_ns is not None else now_ns) + round(
                self.seconds * _NS)
            if p.id not in self._done and now_ns >= due:
                self._done.add(p.id)
                out.append(Event("DWELL", p, due))
        return out


@dataclass
class Within:
    """NEAR when a person is within `metres`, FAR when they are past it by more than
    `margin_m` again (hysteresis: someone standing on the line makes one NEAR)."""

    metres: float
    margin_m: float = 0.2
    _near: set[int] = field(default_factory=set)

    def __post_init__(self) -> None:
        _check("metres", self.metres, positive=True)
        _check("margin_m", self.margin_m)

    def update(self, now_ns: int, persons: tuple[Person, ...]) -> list[Event]:
        self._near &= {p.id for p in persons}
        out = []
        for p in persons:
            if p.distance_m is None:
                continue
            if p.id not in self._near and p.distance_m <= self.metres:
                self._near.add(p.id)
                out.append(Event("NEAR", p, now_ns))
            elif p.id in self._near and p.distance_m > self.metres + self.margin_m:
                self._near.discard(p.id)
                out.append(Event("FAR", p, now_ns))
        return out


@dataclass
class Motion:
    """APPROACHING or RECEDING when a person's distance changes faster than
    `speed_mps` over the last `window_s` (their radial speed from the distances
    the people service gives); again only after they slowed below half of it."""

    speed_mps: float = 0.3
    window_s: float = 1.0
    _seen: dict[int, deque[tuple[int, float]]] = field(default_factory=dict)
    _moving: dict[int, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check("speed_mps", self.speed_mps, positive=True)
        _check("window_s", self.window_s, positive=True)

    def update(self, now_ns: int, persons: tuple[Person, ...]) -> list[Event]:
        present = {p.id for p in persons}
        for gone in set(self._seen) - present:
            del self._seen[gone]
            self._moving.pop(gone, None)
        out = []
        window = round(self.window_s * _NS)
        for p in persons:
            if p.distance_m is None:
                continue
            seen = self._seen.setdefault(p.id, deque())
            if not seen or seen[-1][1] != p.distance_m or now_ns - seen[-1][0] >= window:
                seen.append((now_ns, p.distance_m))
            while len(seen) > 2 and now_ns - seen[0][0] > window:
                seen.popleft()
            span = (seen[-1][0] - seen[0][0]) / _NS
            if span < self.window_s / 2:
                continue
            speed = (seen[0][1] - seen[-1][1]) / span  # + = coming nearer
            kind = ("APPROACHING" if speed >= self.speed_mps else
                    "RECEDING" if speed <= -self.speed_mps else None)
            if kind is not None and self._moving.get(p.id) != kind:
                self._moving[p.id] = kind
                out.append(Event(kind, p, now_ns))
            elif kind is None and abs(speed) < self.speed_mps / 2:
                self._moving.pop(p.id, None)
        return out
