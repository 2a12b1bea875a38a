"""Whom the eyes attend to among the people present, and how they hold eye contact (pure).

The rule, in order: a glance at a newcomer (someone who arrived within
`NEWCOMER_S` and has a direction), then a glance shared with another
person who is engaging, engaged or near while the main person is attended,
else the main person (the visit's person the behaviour follows). Glances
last `glance_s`; the next shared glance comes `share_every_s` (jittered)
after the last, to whoever was looked at longest ago. While the main
person's face is attended, eye contact is broken now and then by a small
gaze aversion (`aversion_deg` for about `aversion_s`, every
`aversion_every_s`, both jittered): a steady stare reads as a machine.
Randomness comes from the `random.Random` passed in (tests seed it).
docs/controller.md, 'Attention', has the why of each number.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from buddybot.controller.kinematics import Person, direction
from buddybot.controller.settings import ControllerSettings

NEWCOMER_S = 1.0
"""A person counts as a newcomer this long after the people service first listed
them (a glance within about a second of their arrival)."""
JITTER = 0.3
"""Intervals and durations vary by up to this fraction either way (irregular, alive)."""
INTERACTING = frozenset({"ENGAGING", "ENGAGED"})
NEAR = frozenset({"INTIMATE", "PERSONAL", "SOCIAL"})
"""A person engaging or engaged, or this near, earns shared glances: the camera
follows one face, so a second visitor standing close may never be ENGAGED."""

Reason = Literal["main", "newcomer", "share"]


@dataclass(frozen=True)
class Focus:
    """Whom to look at (None: nobody with a direction) and why; `offset` (yaw,
    pitch, rad) is the gaze aversion to add now."""

    person_id: int | None
    reason: Reason
    offset: tuple[float, float] = (0.0, 0.0)


@dataclass
class Attention:
    """The attention rule's memory: who was seen and looked at when, the glance and
    aversion under way. `update` is called with every people state and tick."""

    rng: random.Random = field(default_factory=random.Random)
    _first_seen: dict[int, float] = field(default_factory=dict)
    _looked_at: dict[int, float] = field(default_factory=dict)
    _glance: tuple[int, Reason, float] | None = None
    """(person, reason, until) of the glance under way."""
    _next_share: float | None = None
    _averted: tuple[tuple[float, float], float] | None = None
    """(offset, until) of the aversion under way."""
    _next_aversion: float | None = None

    def update(self, s: ControllerSettings, now: float, people: Sequence[Person],
               main: int | None) -> Focus:
        for gone in set(self._first_seen) - {p.id for p in people}:
            del self._first_seen[gone]
            self._looked_at.pop(gone, None)
        first_time = not self._first_seen
        for p in people:
            self._first_seen.setdefault(p.id, now)
        lookable = {p.id: p for p in people if direction(p) is not None}
        focus = self._choose(s, now, lookable, main, first_time)
        if focus.person_id is not None:
            self._looked_at[focus.person_id] = now
        face = focus.reason == "main" and focus.person_id is not None and \
            lookable[focus.person_id].seen_by in ("CAMERA", "BOTH")
        return Focus(focus.person_id, focus.reason, self._aversion(s, now, face))

    def _choose(self, s: ControllerSettings, now: float, lookable: dict[int, Person],
                main: int | None, first_time: bool) -> Focus:
        glance = self._glance
        if glance is not None and (glance[0] not in lookable or now >= glance[2]):
            self._glance = glance = None
        if glance is None and not first_time:
            newcomer = next((pid for pid in lookable if pid != main
                             and pid not in self._looked_at
                             and now - self._first_seen[pid] < NEWCOMER_S), None)
            if newcomer is not None:
                self._glance = glance = (newcomer, "newcomer", now + s.glance_s)
        if glance is None and main in lookable and s.share_every_s > 0:
            others = [pid for pid, p in lookable.items()
                      if pid != main and (p.engagement in INTERACTING or p.zone in NEAR)]
            if not others:
                self._next_share = None
            elif self._next_share is None:
                self._next_share = now + self._jitter(s.share_every_s)
            elif now >= self._next_share:
                other = min(others, key=lambda pid: (self._looked_at.get(pid, -math.inf), pid))
                until = now + self._jitter(s.glance_s)
                self._glance = glance = (other, "share", until)
                self._next_share = until + self._jitter(s.share_every_s)
        if glance is not None:
            return Focus(glance[0], glance[1])
        return Focus(main if main in lookable else None, "main")

    def _aversion(self, s: ControllerSettings, now: float, face: bool) -> tuple[float, float]:
        """The offset now: an aversion runs its course once started; a new one starts
        only while the main person's face is attended."""
        averted = self._averted
        if averted is not None and now < averted[1]:
            return averted[0]
        self._averted = None
        if not face or s.aversion_deg <= 0 or s.aversion_every_s <= 0:
            self._next_aversion = None
            return (0.0, 0.0)
        if self._next_aversion is None:
            self._next_aversion = now + self._jitter(s.aversion_every_s)
        if now < self._next_aversion:
            return (0.0, 0.0)
        size = math.radians(s.aversion_deg)
        # Mostly sideways, a little down (looking down-aside is the common aversion).
        offset = (self.rng.choice((-1.0, 1.0)) * size, -size * self.rng.uniform(0.0, 0.5))
        until = now + self._jitter(s.aversion_s)
        self._averted = (offset, until)
        self._next_aversion = until + self._jitter(s.aversion_every_s)
        return offset

    def _jitter(self, seconds: float) -> float:
        return seconds * self.rng.uniform(1.0 - JITTER, 1.0 + JITTER)
