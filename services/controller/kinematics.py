"""How each person moves, from the people service's positions over a short window (pure).

The behaviour tells a visitor from a passer-by and sees a visitor walk
away by how they move, not only by where they are: a person who keeps
walking (planar speed above a threshold) is passing, one whose distance
keeps growing is leaving. The people service gives distance and, when a
face or an angle radar shows it, a direction; with a distance alone (an
LD2410) only the radial part is known, and the planar speed is taken as
its size. Speeds are averages over `WINDOW_S`, so one noisy distance
does not make a person run; a person's samples start again when the sensors
that show them change (a face's distance and a radar's differ by tens of
centimetres, which would read as a leap).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol


class Person(Protocol):
    """What the behaviour reads of a person (the SDK's `Person` has it); a protocol,
    so the pure decisions load nothing of the SDK."""

    @property
    def id(self) -> int: ...
    @property
    def distance_m(self) -> float | None: ...
    @property
    def yaw_rad(self) -> float | None: ...
    @property
    def bearing_rad(self) -> float | None: ...
    @property
    def seen_by(self) -> str | None: ...
    @property
    def engagement(self) -> str: ...
    @property
    def zone(self) -> str: ...

WINDOW_S = 0.6
"""Speeds are averaged over about this long (a step takes ~0.5 s)."""
MIN_SPAN_S = 0.3
"""A speed is known once the samples span this long."""


@dataclass(frozen=True)
class Moving:
    """A person's motion now: `radial_mps` + = moving away; `speed_mps` planar
    (the radial speed's size when no direction is known)."""

    radial_mps: float
    speed_mps: float
    distance_m: float
    nearest_m: float
    """The nearest they came since they arrived."""
    closer_m: float
    """How much nearer they came over the window (negative: further)."""


@dataclass(frozen=True)
class _Sample:
    t: float
    distance: float
    xy: tuple[float, float] | None
    seen_by: str | None


@dataclass
class Kinematics:
    """Every present person's recent positions; `update` returns their motion."""

    _seen: dict[int, deque[_Sample]] = field(default_factory=dict)
    _nearest: dict[int, float] = field(default_factory=dict)

    def update(self, now: float, people: Sequence[Person]) -> dict[int, Moving]:
        present = {p.id for p in people}
        for gone in set(self._seen) - present:
            del self._seen[gone]
            self._nearest.pop(gone, None)
        out: dict[int, Moving] = {}
        for p in people:
            if p.distance_m is None:
                continue
            seen = self._seen.setdefault(p.id, deque())
            if seen and seen[-1].seen_by != p.seen_by:
                seen.clear()
            seen.append(_Sample(now, p.distance_m, _xy(p), p.seen_by))
            while len(seen) > 2 and now - seen[1].t >= WINDOW_S:
                seen.popleft()
            nearest = min(self._nearest.get(p.id, math.inf), p.distance_m)
            self._nearest[p.id] = nearest
            first, last = seen[0], seen[-1]
            span = last.t - first.t
            if span < MIN_SPAN_S:
                continue
            radial = (last.distance - first.distance) / span
            if first.xy is not None and last.xy is not None:
                speed = math.dist(first.xy, last.xy) / span
            else:
                speed = abs(radial)
            out[p.id] = Moving(radial, speed, last.distance, nearest,
                               first.distance - last.distance)
        return out


def direction(person: Person) -> float | None:
    """Their direction (rad, + = left of the camera): the face's, else the angle
    radar's bearing; None when only a distance is known."""
    return person.yaw_rad if person.yaw_rad is not None else person.bearing_rad


def _xy(person: Person) -> tuple[float, float] | None:
    yaw = direction(person)
    if yaw is None or person.distance_m is None:
        return None
    return person.distance_m * math.cos(yaw), person.distance_m * math.sin(yaw)
