"""The dashboard's known-people panel: its requests, views and bus calls (pure,
with a fake node; the page itself is in test_dashboard_page.py)."""

from __future__ import annotations

from typing import Any

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.dashboard import identity, model
from buddybot.runtime.errors import CallError, NoReplyError

T0 = 1_700_000_000_000_000_000


def test_the_panels_requests_are_page_commands() -> None:
    assert model.parse_command('{"op": "enrol", "name": "Ada", "id": 3}') == \
        identity.EnrolFace(name="Ada", id=3)
    assert model.parse_command('{"op": "forget", "name": "Ada"}') == identity.ForgetFace("Ada")
    assert model.parse_command('{"op": "known"}') == identity.ListKnown()


@pytest.mark.parametrize("text", ['{"op": "enrol", "name": ""}',
                                  '{"op": "enrol", "name": "' + "x" * 65 + '"}',
                                  '{"op": "forget"}', '{"op": "enrol", "name": 5}'])
def test_a_bad_name_is_a_bad_command(text: str) -> None:
    with pytest.raises(model.BadCommand):
        model.parse_command(text)


def test_the_list_is_sorted_by_name_with_times_in_seconds() -> None:
    view = identity.known_view(m.KnownPeople(people=[
        m.KnownPerson(name="grace", enrolled_ns=T0, samples=5),
        m.KnownPerson(name="Ada", enrolled_ns=T0, last_seen_ns=T0 + 10**9, samples=3)]))
    assert [p["name"] for p in view["people"]] == ["Ada", "grace"]
    assert view["people"][0]["last_seen"] == pytest.approx(T0 / 1e9 + 1)
    assert view["people"][1]["last_seen"] is None
    assert identity.known_view(None, "why") == {"known": False, "error": "why", "people": []}


def test_present_people_carry_their_names() -> None:
    person = m.Person(id=2, distance_m=1.0, zone="PERSONAL", seen_by="BOTH", zone_since_ns=1,
                      arrived_ns=1, engagement="NONE", engagement_since_ns=1, name="Ada")
    assert identity.present_view(m.PeopleState(stamp_ns=1, people=[person])) == [
        {"id": 2, "name": "Ada", "seen_by": "BOTH"}]


class FakeNode:
    """Answers the identity calls from a table; records what was asked."""

    def __init__(self, answers: dict[str, Any]) -> None:
        self.answers = answers
        self.asked: list[tuple[str, Any, float]] = []

    def call(self, service: keys.Service, request: Any, *, timeout: float) -> Any:
        self.asked.append((service.pattern, request, timeout))
        answer = self.answers[service.pattern]
        if isinstance(answer, Exception):
            raise answer
        return answer


LISTED = m.KnownPeople(people=[m.KnownPerson(name="Ada", enrolled_ns=T0, samples=5)])


def test_enrol_asks_the_identity_service_then_lists_again() -> None:
    node = FakeNode({"identity/enrol": m.EnrolReply(success=True, name="Ada", samples=5),
                     "identity/list": LISTED})
    ok, text, known = identity.run(node, identity.EnrolFace(" Ada "))  # type: ignore[arg-type]
    assert (ok, text) == (True, "remembered Ada (5 samples)")
    asked = node.asked[0][1]
    assert isinstance(asked, m.EnrolRequest) and asked.name == "Ada" and asked.sent_ns > 0
    assert node.asked[0][2] == 15.0
    assert known is not None and [p["name"] for p in known["people"]] == ["Ada"]


def test_refusals_and_a_missing_service_are_said_plainly() -> None:
    node = FakeNode({"identity/enrol": m.EnrolReply(success=False, message="no face"),
                     "identity/forget": m.ForgetReply(success=False, message="nobody called Bo"),
                     "identity/list": LISTED})
    assert identity.run(node, identity.EnrolFace("Ada"))[:2] == (  # type: ignore[arg-type]
        False, "not remembered: no face")
    assert identity.run(node, identity.ForgetFace("Bo"))[:2] == (  # type: ignore[arg-type]
        False, "not forgotten: nobody called Bo")
    gone = FakeNode({"identity/list": NoReplyError("identity/list", "no reply"),
                     "identity/forget": CallError("identity/forget", "bad reply")})
    ok, text, known = identity.run(gone, identity.ListKnown())  # type: ignore[arg-type]
    assert (ok, text) == (False, identity.NOT_RUNNING)
    assert known == identity.known_view(None, identity.NOT_RUNNING)
    ok, text, known = identity.run(gone, identity.ForgetFace("Ada"))  # type: ignore[arg-type]
    assert not ok and "bad reply" in text and known is None
