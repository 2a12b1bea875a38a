"""The controller's inbox vocabulary: what the SDK's callbacks and the sound thread
tell the decision thread.

Each event is a small frozen dataclass, and `Event` is their union, so the
decision thread dispatches with an exhaustive `match` that a type checker
verifies: a new event that nobody handles is a type error (`assert_never`),
not a string tag silently falling through an if-chain. Events are frozen
because they cross threads: the poster must not change one after handing it
over.

They live apart from `behaviour.py` because they are the service's plumbing
(who posted what), while `Behaviour` keeps its plain method API (`presence`,
`sound_reply`, ...) that the pure tests drive directly. Faces are not events:
a face is decided in its callback (the gaze's latency path), so a fast
camera neither waits for the decision thread nor fills the inbox.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from buddybot.contract import messages as m
from buddybot.controller.transform import Gaze
from buddybot.sdk.persons import Person


@dataclass(frozen=True, slots=True)
class PeopleChanged:
    """What the controller takes from `people/state` (latched): whether a person a
    sensor shows now is present (`in_range`), or only one the people service
    holds though no sensor shows them (`held`), the people service's id of the
    person followed and their name, if it knows them."""

    in_range: bool
    person_id: int | None = None
    name: str | None = None
    held: bool = False
    face: bool = False
    """The people service shows that person's face now (`seen_by` CAMERA or BOTH)."""


def people_changed(people: Sequence[Person], follow: int | None = None) -> PeopleChanged:
    """The controller's presence from the people service's persons, taken as they
    are: the people service alone decides who is there and for how long a
    person nobody sees any more is held (its `absence_hold_s`), so the controller
    adds no hold of its own (docs/design.md 4.3).

    The person followed is `follow` while present and shown by a sensor (angle
    radars show several persons: the eyes do not hop to whoever steps nearer),
    else the nearest shown (the lowest id on a tie), else, while everyone is
    held, the one followed or the nearest held.
    """
    if not people:
        return PeopleChanged(False)
    shown = [p for p in people if p.seen_by != "NONE"]
    pool = shown or people
    followed = next((p for p in pool if p.id == follow), None) if follow is not None else None
    person = followed or min(pool, key=lambda p: (_distance(p), p.id))
    return PeopleChanged(bool(shown), person.id, person.name, held=not shown,
                         face=person.seen_by in ("CAMERA", "BOTH"))


@dataclass(frozen=True, slots=True)
class RadarGaze:
    """The followed person's direction from an angle radar, as a gaze in the eyes
    frame (None: no angle radar tracks them), with the stamp of `people/state`."""

    gaze: Gaze | None
    stamp_ns: int | None = None


def _distance(person: Person) -> float:
    return math.inf if person.distance_m is None else person.distance_m


def radar_point(people: Sequence[Person],
                person_id: int | None) -> tuple[float, float, float] | None:
    """Where the followed person is in the camera's frame by their angle-radar
    track: their bearing and distance, at their `pitch_rad` (the last face's, or
    0: the camera's level). None when no angle radar tracks them."""
    person = next((p for p in people if p.id == person_id), None)
    if person is None or person.bearing_rad is None or person.distance_m is None:
        return None
    d, bearing = person.distance_m, person.bearing_rad
    pitch = person.pitch_rad or 0.0
    return (d * math.cos(bearing), d * math.sin(bearing), d * math.tan(pitch))


@dataclass(frozen=True, slots=True)
class Crowd:
    """Everyone `people/state` lists, and where each one with a direction is as a
    gaze in the eyes frame: attention and motion read every state (the inbox
    keeps only the newest one not yet handled)."""

    people: tuple[Person, ...]
    gazes: dict[int, Gaze]
    stamp_ns: int


def person_point(person: Person) -> tuple[float, float, float] | None:
    """Where a person is in the camera's frame: by their face's direction when the
    people service has one, else by their angle-radar track (`radar_point`)."""
    if person.distance_m is None:
        return None
    if person.yaw_rad is None:
        return radar_point((person,), person.id)
    d, yaw, pitch = person.distance_m, person.yaw_rad, person.pitch_rad or 0.0
    return (d * math.cos(pitch) * math.cos(yaw), d * math.cos(pitch) * math.sin(yaw),
            d * math.sin(pitch))


@dataclass(frozen=True, slots=True)
class DeviceFree:
    """`audio/device_free`: the player is idle (it may be busy with another program)."""

    free: bool


@dataclass(frozen=True, slots=True)
class SoundStatus:
    """`audio/play_sound/status`; `age_s` is how old the status is (None: unknown),
    which matters for a latched status replayed to a restarted controller."""

    goal_id: str
    state: str
    age_s: float | None


@dataclass(frozen=True, slots=True)
class GoalReply:
    """The answer to a `PlaySound` command; a failed call is `accepted=False, goal_id=""`."""

    request: int
    accepted: bool
    goal_id: str


@dataclass(frozen=True, slots=True)
class CancelReply:
    """The answer to a `CancelSound` command; a failed call is `success=False`."""

    goal_id: str
    success: bool


@dataclass(frozen=True, slots=True)
class Yielded:
    """What the leases of `leases/state` hold now: the eyes driver shows those
    parts for their holders, and a held speaker keeps the behaviour silent."""

    resources: tuple[m.Resource, ...]


Event = (PeopleChanged | RadarGaze | Crowd | DeviceFree | SoundStatus | GoalReply | CancelReply
         | Yielded)
