"""`bot.people.enrol/known/forget/forget_all`: the contract check (pure), then the
calls against a real router and a stand-in for the identity service's queryables
(the SDK's answers and errors are tested here, not the identity service)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import Bot, KnownPerson, NoService, Refused
from buddybot.sdk.identity import checked
from buddybot.sdk.people import PeopleView
from buddybot.tools.testing import retry_until
from tests.cli.test_people import FakeIdentity

T0 = 1_700_000_000_000_000_000


@pytest.mark.parametrize(("fields", "where"), [
    ({"name": ""}, "name"), ({"name": "x" * 65}, "name"),
    ({"name": "Ada", "samples": 17}, "samples"), ({"name": "Ada", "timeout_s": 0.0},
                                                  "timeout_s")])
def test_a_request_outside_the_contract_is_a_value_error(fields: dict[str, object],
                                                        where: str) -> None:
    with pytest.raises(ValueError, match=f"^{where}: "):
        checked(m.EnrolRequest, **fields)


def test_a_person_carries_the_name_of_people_state() -> None:
    view = PeopleView()
    view.on_state(m.PeopleState(stamp_ns=T0, people=[m.Person(
        id=1, distance_m=1.0, zone="PERSONAL", seen_by="BOTH", zone_since_ns=T0,
        arrived_ns=T0, engagement="ENGAGED", engagement_since_ns=T0, name="Ada")]))
    assert [p.name for p in view.present()] == ["Ada"]


@pytest.mark.integration
def test_enrol_known_forget_through_the_sdk(
        bot_factory: Callable[..., Bot], node_factory: Callable[..., Node],
        probe: Node) -> None:
    bot = bot_factory(timeout=2.0)
    with pytest.raises(NoService, match="identity"):
        bot.people.known()
    identity = FakeIdentity(node_factory("identity"))
    retry_until(lambda: any(keys.IDENTITY_LIST.key() in i.services
                            for i in probe.node_infos(1.0)), 30, 0.2, "identity queryables")
    assert bot.people.enrol(" Ada ", samples=3) == 3
    asked = identity.requests[-1]
    assert isinstance(asked, m.EnrolRequest)
    assert (asked.name, asked.samples, asked.credential) == ("Ada", 3, "") and asked.sent_ns > 0
    with pytest.raises(Refused, match="already enrolled"):
        bot.people.enrol("Ada")
    assert bot.people.enrol("Ada", replace=True, timeout_s=2.0) == 5
    with pytest.raises(ValueError, match="name"):
        bot.people.enrol("")
    bot.people.enrol("Grace")
    known = bot.people.known()
    assert [p.name for p in known] == ["Ada", "Grace"]
    assert isinstance(known[0], KnownPerson) and known[0].last_seen_ns is None
    bot.people.forget("Ada")
    with pytest.raises(Refused, match="nobody called Ada"):
        bot.people.forget("Ada")
    assert bot.people.forget_all() == ["Grace"]
    assert bot.people.known() == ()
