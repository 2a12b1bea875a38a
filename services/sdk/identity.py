"""Enrolment, the known people and erasure: the identity service's three calls.

`bot.people.enrol/known/forget/forget_all` call these. Enrolling is the
explicit act of consent (docs/identity.md): a program calls it only when
the person in front of the camera asked to be known. A request outside the
contract (an empty or over 64-character name, samples outside 1-16) is a
ValueError before anything is sent; a refusal of the service (no face, two
faces, a name already enrolled, an unknown name) is `Refused` with its
words; nobody answering is `NoService`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk.calls import call
from buddybot.sdk.errors import Refused

HINT = "is the identity service running? enable [identity]"
ENROL_MARGIN_S = m.ENROL_MARGIN_S

Req = TypeVar("Req", bound=m.Message)


@dataclass(frozen=True)
class KnownPerson:
    """An enrolled person, without their templates (those never leave the service)."""

    name: str
    enrolled_ns: int
    last_seen_ns: int | None
    """Last recognised; None: not since enrolment."""
    samples: int


def checked(kind: type[Req], **fields: object) -> Req:
    """A request checked against the contract; ValueError "FIELD: why" otherwise."""
    try:
        return msgspec.convert(fields, kind)
    except msgspec.ValidationError as exc:
        reason, _, where = str(exc).partition(" - at `$.")
        raise ValueError(f"{where.rstrip('`') or 'request'}: {reason}") from None


def enrol(node: Node, name: str, samples: int = 5, timeout_s: float = 10.0,
          replace: bool = False, credential: str = "") -> int:
    """Remember the one face in front of the camera under `name`; the samples stored."""
    req = checked(m.EnrolRequest, name=name.strip(), samples=samples, timeout_s=timeout_s,
                  replace=replace, credential=credential, sent_ns=m.now_ns())
    reply: m.EnrolReply = call(node, keys.IDENTITY_ENROL, req, req.timeout_s + ENROL_MARGIN_S,
                               hint=HINT)
    if not reply.success:
        raise Refused(reply.message or f"{req.name} not enrolled")
    return reply.samples


def known(node: Node, timeout: float) -> tuple[KnownPerson, ...]:
    """Everybody enrolled, by name."""
    reply: m.KnownPeople = call(node, keys.IDENTITY_LIST, m.Trigger(), timeout, hint=HINT)
    return tuple(sorted((KnownPerson(p.name, p.enrolled_ns, p.last_seen_ns, p.samples)
                         for p in reply.people), key=lambda p: p.name.casefold()))


def forget(node: Node, timeout: float, name: str | None = None,
           credential: str = "") -> list[str]:
    """Erase `name`'s templates, or everybody's (None); the names erased."""
    req = (checked(m.ForgetRequest, all=True, credential=credential) if name is None
           else checked(m.ForgetRequest, name=name.strip(), credential=credential))
    reply: m.ForgetReply = call(node, keys.IDENTITY_FORGET, req, timeout, hint=HINT)
    if not reply.success:
        raise Refused(reply.message or f"{name} not forgotten")
    return list(reply.forgotten)
