"""The controller's typed inbox: each callback posts its event, and the decision
step hands every event to the right `Behaviour` method; the people service's
state becomes the controller's presence (`people_changed`, pure). A fake node
stands in for Zenoh, so this runs without a router."""

from __future__ import annotations

from typing import Any

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.controller.behaviour import CancelSound, PlaySound
from buddybot.controller.events import (
    CancelReply,
    Crowd,
    DeviceFree,
    GoalReply,
    PeopleChanged,
    SoundStatus,
    people_changed,
)
from buddybot.controller.service import Controller
from buddybot.controller.settings import ControllerSettings
from buddybot.sdk.persons import PeopleNow, Person
from buddybot.sdk.speaker import GoalStatus
from buddybot.tools.testing import visitor

from .fakes import Clock, FakeBot, attached, face, people_now

A = m.ExpressionAction


@pytest.fixture
def rig() -> tuple[Controller, FakeBot, Clock]:
    settings = msgspec.convert({"recover_s": 0.0, "greet_dwell_s": 0.0, "farewell_delay_s": 0.0,
                                "sleepy_s": 0.0}, ControllerSettings)
    clock = Clock()
    return (*attached(settings, clock), clock)


def drain(controller: Controller) -> list[Any]:
    """One decision step's worth of events, handled as `_decide` does."""
    events = list(controller._inbox)
    controller._inbox.clear()
    controller._handle(events)
    return events


def expressions(node: FakeBot) -> list[A]:
    return [msg.action for msg in node.publishers["controller/expression"].sent]


def commanded(controller: Controller) -> list[Any]:
    out = []
    while not controller._sounds.empty():
        out.append(controller._sounds.get_nowait())
    return out


def test_callbacks_post_typed_events(rig: tuple[Controller, FakeBot, Clock]) -> None:
    controller, _node, _clock = rig
    controller._on_people(people_now(visitor(True, person_id=4)))
    controller._on_device_free(False)
    controller._on_status(GoalStatus("g", "PLAYING", "", 0))
    events = drain(controller)
    assert [e for e in events if not isinstance(e, Crowd)] == [
        PeopleChanged(True, 4), DeviceFree(False), SoundStatus("g", "PLAYING", None)]
    [crowd] = [e for e in events if isinstance(e, Crowd)]
    assert [p.id for p in crowd.people] == [4] and crowd.gazes == {}  # no direction known


def test_only_the_newest_crowd_waits_in_the_inbox(
        rig: tuple[Controller, FakeBot, Clock]) -> None:
    controller, _node, _clock = rig
    for i, distance in enumerate((2.0, 1.9, 1.8)):
        controller._on_people(people_now(visitor(True, person_id=4, distance_m=distance,
                                                 stamp_ns=10**9 + i * 10**8)))
    crowds = [e for e in controller._inbox if isinstance(e, Crowd)]
    assert [c.people[0].distance_m for c in crowds] == [1.8]


def test_the_crowd_comes_every_tenth_of_a_second_or_when_who_is_there_changes(
        rig: tuple[Controller, FakeBot, Clock]) -> None:
    controller, _node, _clock = rig
    posted = []
    for ms, shown in ((0, False), (30, False), (60, False), (70, True), (100, True),
                      (200, True)):
        controller._on_people(people_now(visitor(True, person_id=4, face=shown,
                                                 stamp_ns=10**9 + ms * 10**6)))
        posted += [ms for e in drain(controller) if isinstance(e, Crowd)]
    assert posted == [0, 70, 200]  # a camera frame's state in between: nothing new


def test_every_event_reaches_the_behaviour(rig: tuple[Controller, FakeBot, Clock]) -> None:
    controller, node, clock = rig
    controller._post(PeopleChanged(True, 1))
    drain(controller)
    assert expressions(node) == [A.EYE_AWAKE]
    # A face is looked at in the callback itself; the people service showing it
    # makes the greeting; the goal's reply and status then end it.
    controller._on_face(face(1.0, 0.0, 0.0, stamp_ns=1))
    assert node.publishers["controller/eye_control"].sent[-1].stamp_ns == 1
    assert commanded(controller) == []
    controller._post(PeopleChanged(True, 1, face=True))
    drain(controller)
    [play] = commanded(controller)
    assert isinstance(play, PlaySound) and play.sound == "greeting"
    assert expressions(node)[-1] == A.EYE_GRIN
    controller._post(GoalReply(play.request, True, "g1"))
    controller._post(SoundStatus("g1", "PLAYING", 0.0))
    drain(controller)
    assert controller.behaviour.sound_busy()
    # The visitor leaves while it plays: the greeting is cancelled for the farewell.
    clock.t += 1.0
    controller._post(PeopleChanged(False))
    drain(controller)
    [cancel] = commanded(controller)
    assert cancel == CancelSound("g1")
    controller._post(CancelReply("g1", True))
    controller._post(SoundStatus("g1", "CANCELED", 0.0))
    controller._post(DeviceFree(True))
    drain(controller)
    [farewell] = commanded(controller)
    assert isinstance(farewell, PlaySound) and farewell.sound == "farewell"


def test_an_unknown_event_is_an_error_not_ignored(
    rig: tuple[Controller, FakeBot, Clock],
) -> None:
    controller, _node, _clock = rig
    with pytest.raises(AssertionError):
        controller._handle([("presence", (True,))])  # type: ignore[list-item]


def test_an_unknown_command_is_an_error_not_played_as_a_sound(
    rig: tuple[Controller, FakeBot, Clock],
) -> None:
    controller, node, _clock = rig
    with pytest.raises(AssertionError):
        controller._execute(["greeting"])  # type: ignore[list-item]
    assert commanded(controller) == []
    assert not any(pub.sent for pub in node.publishers.values())


# --- people/state -> the controller's presence ------------------------------------------


def person(pid: int, seen_by: m.SeenBy, distance_m: float = 1.0) -> m.Person:
    return m.Person(id=pid, distance_m=distance_m, zone="PERSONAL", seen_by=seen_by,
                    zone_since_ns=1, arrived_ns=1, engagement="NONE", engagement_since_ns=1)


def people(*persons: m.Person) -> PeopleNow:
    return people_now(m.PeopleState(stamp_ns=5, people=list(persons)))


def crowd(*persons: m.Person) -> tuple[Person, ...]:
    """The persons of a `people/state`, as the SDK gives them."""
    return people(*persons).people


@pytest.mark.parametrize(("seen_by", "expected"), [
    ("RADAR", PeopleChanged(True, 7)), ("BOTH", PeopleChanged(True, 7, face=True)),
    ("CAMERA", PeopleChanged(True, 7, face=True)),
    ("NONE", PeopleChanged(False, 7, held=True))])
def test_a_person_present_is_in_range_while_shown_and_held_while_missed(
        seen_by: m.SeenBy, expected: PeopleChanged) -> None:
    """The people service's persons as they are: shown by either sensor is in range,
    missed (`seen_by` NONE, held by the people service) is held, not gone; shown
    by the camera is a face seen."""
    assert people_changed(crowd(person(7, seen_by))) == expected


def test_nobody_present_is_out_of_range() -> None:
    assert people_changed(crowd()) == PeopleChanged(False, None)


def test_the_nearest_person_shown_is_the_one_whatever_the_order() -> None:
    near, far = person(3, "CAMERA", 0.8), person(2, "BOTH", 2.5)
    missed = person(9, "NONE", 0.3)  # nearer, but held: no sensor shows them now
    for order in ((near, far, missed), (missed, far, near)):
        assert people_changed(crowd(*order)) == PeopleChanged(True, 3, face=True)
    tie = (person(5, "RADAR", 1.0), person(4, "RADAR", 1.0))
    assert people_changed(crowd(*tie)) == people_changed(crowd(*reversed(tie))) == \
        PeopleChanged(True, 4)
    # Everyone held: the one followed, else the nearest.
    held = (person(5, "NONE", 2.0), person(6, "NONE", 1.0))
    assert people_changed(crowd(*held)) == PeopleChanged(False, 6, held=True)
    assert people_changed(crowd(*held), follow=5) == PeopleChanged(False, 5, held=True)


def test_the_followed_persons_name_comes_with_them_and_its_change_is_news() -> None:
    ada = msgspec.structs.replace(person(3, "BOTH"), name="Ada")
    assert people_changed(crowd(ada, person(4, "RADAR", 2.0))) == PeopleChanged(
        True, 3, "Ada", face=True)
    unnamed = crowd(person(3, "BOTH"))
    assert people_changed(unnamed, follow=3) == PeopleChanged(True, 3, None, face=True)


def test_only_a_change_of_who_is_in_range_reaches_the_inbox(
    rig: tuple[Controller, FakeBot, Clock],
) -> None:
    """people/state changes with every face frame (distance, direction): the same
    presence again posts no presence; another person, the sensors losing them
    (held), or their leaving does (the crowd is posted each time, for attention)."""
    controller, _node, _clock = rig
    for distance in (1.0, 1.1, 1.2):
        controller._on_people(people_now(visitor(True, person_id=1, distance_m=distance)))
    controller._on_people(people_now(visitor(True, person_id=2)))
    controller._on_people(people_now(visitor(False, person_id=2, held=True)))
    controller._on_people(people())  # then gone
    presence = [e for e in drain(controller) if not isinstance(e, Crowd)]
    assert presence == [PeopleChanged(True, 1), PeopleChanged(True, 2),
                        PeopleChanged(False, 2, held=True), PeopleChanged(False)]
