"""A person and an event about them, as a program sees them (plain values)."""

from __future__ import annotations

from dataclasses import dataclass

from buddybot.contract import messages as m


@dataclass(frozen=True)
class Person:
    """One person. Fields the event alone does not carry (distance, direction,
    arrival) come from the latest `people/state` and are None when unknown."""

    id: int
    zone: str
    engagement: str
    distance_m: float | None = None
    seen_by: str | None = None
    arrived_ns: int | None = None
    yaw_rad: float | None = None
    pitch_rad: float | None = None
    name: str | None = None
    """Who they are, once the identity service recognised them (None: unknown)."""
    bearing_rad: float | None = None
    """Their bearing by an angle radar (+ = left; None: no angle radar tracks them)."""


@dataclass(frozen=True)
class PeopleNow:
    """Everyone the people service lists in one `people/state`, as it published them
    (`bot.people.on_state`): persons shown by a sensor and persons it holds."""

    people: tuple[Person, ...]
    stamp_ns: int


@dataclass(frozen=True)
class Event:
    """Something that happened to a person (`kind`: one of the people service's
    `people.KINDS`, or of the derived `triggers.DERIVED`).

    `replayed`: synthesized from the state present when the subscription was
    made (an ARRIVED stamped with the person's arrival), not a change now."""

    kind: str
    person: Person
    stamp_ns: int
    replayed: bool = False


def person_from(msg: m.Person) -> Person:
    return Person(id=msg.id, zone=msg.zone, engagement=msg.engagement,
                  distance_m=msg.distance_m, seen_by=msg.seen_by, arrived_ns=msg.arrived_ns,
                  yaw_rad=msg.yaw_rad, pitch_rad=msg.pitch_rad, name=msg.name,
                  bearing_rad=msg.bearing_rad)
