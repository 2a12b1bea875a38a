"""The dashboard's "Known people" panel: enrol the face in front of the camera,
list the enrolled people, forget one, and show who is present by name.

Enrolling and forgetting act only under the dashboard's operator lease (the
switch "Take control"): remembering a face is the explicit act of consent
(docs/identity.md), never a stray click. Listing is read-only. The requests
(`EnrolFace`, `ForgetFace`, `ListKnown`) join the page's commands
(`model.Command`); `run` carries one out on the bus in a worker thread and
returns the page's reply and the list to show (None: unchanged).
"""

from __future__ import annotations

from typing import Annotated, Any

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import NoReplyError, ServiceError
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node
from buddybot.runtime.private_files import operator_secret as operator_credential

NOT_RUNNING = "the identity service does not answer (is [identity] enabled?)"
ENROL_MARGIN_S = m.ENROL_MARGIN_S
LIST_TIMEOUT_S = 3.0

_Id = Annotated[int, msgspec.Meta(ge=0, le=2**53)]


class EnrolFace(msgspec.Struct, tag="enrol", tag_field="op", forbid_unknown_fields=True):
    """Remember the one face in front of the camera under `name` (operator only)."""
    name: Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
    id: _Id = 0


class ForgetFace(msgspec.Struct, tag="forget", tag_field="op", forbid_unknown_fields=True):
    """Erase one enrolled person's templates (operator only)."""
    name: Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
    id: _Id = 0


class ListKnown(msgspec.Struct, tag="known", tag_field="op", forbid_unknown_fields=True):
    """Ask for the enrolled people again."""
    id: _Id = 0


Request = EnrolFace | ForgetFace | ListKnown


# --- what the page shows (pure) ------------------------------------------------------------


def known_view(reply: m.KnownPeople | None, error: str = "") -> dict[str, Any]:
    """The panel's list: names with enrolment and last-seen times (s), or why none."""
    if reply is None:
        return {"known": False, "error": error, "people": []}
    people = sorted(reply.people, key=lambda p: p.name.casefold())
    return {"known": True, "error": "", "retention_days": reply.retention_days,
            "people": [{"name": p.name, "enrolled": p.enrolled_ns / 1e9,
                        "last_seen": None if p.last_seen_ns is None else p.last_seen_ns / 1e9,
                        "samples": p.samples} for p in people]}


def present_view(state: m.PeopleState) -> list[dict[str, Any]]:
    """Who is present now, by id, with their name (None: not recognised)."""
    return [{"id": p.id, "name": p.name, "seen_by": p.seen_by} for p in state.people]


# --- on the bus (a worker thread) ----------------------------------------------------------


def run(node: Node, req: Request) -> tuple[bool, str, dict[str, Any] | None]:
    """Carry out `req`: (ok, the page's reply text, the list to show or None)."""
    try:
        if isinstance(req, EnrolFace):
            name = req.name.strip()
            asked = m.EnrolRequest(name=name, credential=operator_credential(),
                                   sent_ns=m.now_ns())
            enrolled: m.EnrolReply = node.call(keys.IDENTITY_ENROL, asked,
                                               timeout=asked.timeout_s + ENROL_MARGIN_S)
            text = (f"remembered {clip(enrolled.name or name, 64)} "
                    f"({enrolled.samples} samples)" if enrolled.success
                    else f"not remembered: {clip(enrolled.message, 200)}")
            return enrolled.success, text, _listed(node)
        if isinstance(req, ForgetFace):
            forgot: m.ForgetReply = node.call(
                keys.IDENTITY_FORGET, m.ForgetRequest(name=req.name.strip(),
                                                      credential=operator_credential()),
                timeout=LIST_TIMEOUT_S)
            text = (f"forgot {clip(req.name, 64)}" if forgot.success
                    else f"not forgotten: {clip(forgot.message, 200)}")
            return forgot.success, text, _listed(node)
        view = _listed(node)
        return bool(view["known"]), view["error"] or "known people listed", view
    except NoReplyError:
        return False, NOT_RUNNING, known_view(None, NOT_RUNNING)
    except ServiceError as exc:
        return False, clip(exc, 200), None


def _listed(node: Node) -> dict[str, Any]:
    try:
        reply: m.KnownPeople = node.call(keys.IDENTITY_LIST, m.Trigger(),
                                         timeout=LIST_TIMEOUT_S)
    except NoReplyError:
        return known_view(None, NOT_RUNNING)
    except ServiceError as exc:
        return known_view(None, clip(exc, 200))
    return known_view(reply)
