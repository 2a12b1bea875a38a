"""`buddybot.sdk.people`: the view and its replay (pure), the streams both ways, and,
marked `integration`, a real `people` service fed presence: live and replayed ARRIVED."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import Bot, Event, EventStream, NoService, Person, SdkError, TimedOut
from buddybot.sdk.people import KINDS, PeopleView, check_kinds
from buddybot.tools.testing import Collector, Process, retry_until
from tests.people.test_service import Visitor
from tests.sdk.conftest import start_people

S = 1_000_000_000
T0 = 1_700_000_000 * S


def _person(pid: int, arrived: int = T0, zone: m.Zone = "SOCIAL") -> m.Person:
    return m.Person(id=pid, distance_m=2.0, zone=zone, seen_by="RADAR", zone_since_ns=arrived,
                    arrived_ns=arrived, engagement="NONE", engagement_since_ns=arrived)


def _state(*people: m.Person, stamp: int = T0) -> m.PeopleState:
    return m.PeopleState(stamp_ns=stamp, people=list(people))


def _event(pid: int, kind: m.PersonEventKind, stamp: int = T0,
           engagement: m.Engagement = "NONE") -> m.PersonEvent:
    return m.PersonEvent(stamp_ns=stamp, person_id=pid, kind=kind, zone="PERSONAL",
                         engagement=engagement)


# --- the view and its replay -------------------------------------------------------------


def test_a_person_in_the_state_is_replayed_as_arrived_at_their_arrival() -> None:
    view = PeopleView()
    view.on_state(_state(_person(3, arrived=T0 - 10 * S), stamp=T0))
    [event] = view.replay(frozenset(KINDS))
    assert (event.kind, event.replayed, event.stamp_ns) == ("ARRIVED", True, T0 - 10 * S)
    assert event.person == Person(id=3, zone="SOCIAL", engagement="NONE", distance_m=2.0,
                                  seen_by="RADAR", arrived_ns=T0 - 10 * S)


def test_nothing_is_replayed_for_other_kinds_or_an_empty_state() -> None:
    view = PeopleView()
    view.on_state(_state(_person(1)))
    assert view.replay(frozenset({"LEFT", "ZONE_CHANGED"})) == []
    view.on_state(_state())
    assert view.replay(frozenset(KINDS)) == []


def test_a_live_arrival_not_yet_in_the_state_is_present() -> None:
    view = PeopleView()
    view.on_state(_state())
    live = view.on_event(_event(7, "ARRIVED", T0 + S))
    assert not live.replayed and live.person.arrived_ns == T0 + S
    assert [p.id for p in view.present()] == [7]
    view.on_state(_state(_person(7, arrived=T0 + S)))
    assert [p.id for p in view.present()] == [7]


def test_a_live_departure_hides_a_person_the_state_still_lists() -> None:
    view = PeopleView()
    view.on_state(_state(_person(2)))
    view.on_event(_event(2, "LEFT", T0 + S, engagement="GONE"))
    assert view.present() == ()
    view.on_state(_state())
    assert view.present() == ()


def test_a_live_event_is_completed_from_the_state() -> None:
    view = PeopleView()
    view.on_state(_state(_person(4)))
    event = view.on_event(_event(4, "ENGAGEMENT_CHANGED", T0 + S, engagement="ENGAGING"))
    assert (event.person.distance_m, event.person.zone, event.person.engagement) == (
        2.0, "PERSONAL", "ENGAGING")
    unknown = view.on_event(_event(9, "ZONE_CHANGED", T0 + S))
    assert unknown.person == Person(id=9, zone="PERSONAL", engagement="NONE")


def test_unknown_kinds_are_refused_naming_the_known_ones() -> None:
    assert check_kinds(()) == frozenset(KINDS)
    with pytest.raises(ValueError, match=r"ARRIVD.*known: ARRIVED"):
        check_kinds(["ARRIVD"])


# --- streams -----------------------------------------------------------------------------


def _ev(kind: str, pid: int = 1, replayed: bool = False) -> Event:
    return Event(kind=kind, person=Person(id=pid, zone="SOCIAL", engagement="NONE"),
                 stamp_ns=T0, replayed=replayed)


def test_a_stream_keeps_only_its_kinds_and_one_arrival_per_person() -> None:
    stream = EventStream(frozenset({"ARRIVED", "LEFT"}))
    for event in [_ev("ARRIVED", 1, replayed=True), _ev("ZONE_CHANGED"), _ev("ARRIVED", 1),
                  _ev("ARRIVED", 2), _ev("LEFT", 1)]:
        stream.push(event)
    got = [stream.get(1.0) for _ in range(3)]
    assert [(e.kind, e.person.id, e.replayed) for e in got] == [
        ("ARRIVED", 1, True), ("ARRIVED", 2, False), ("LEFT", 1, False)]
    with pytest.raises(TimedOut, match=r"within 0\.05 s"):
        stream.get(0.05)


def test_closing_ends_sync_iteration_and_get() -> None:
    closed: list[EventStream] = []
    stream = EventStream(frozenset(KINDS), on_close=closed.append)
    stream.push(_ev("ARRIVED"))
    seen: list[Event] = []
    reader = threading.Thread(target=lambda: seen.extend(stream))
    reader.start()
    stream.push(_ev("LEFT"))
    while len(seen) < 2 and reader.is_alive():
        reader.join(0.01)
    stream.unsubscribe()
    reader.join(10)
    assert not reader.is_alive() and [e.kind for e in seen] == ["ARRIVED", "LEFT"]
    assert closed == [stream]
    with pytest.raises(SdkError, match="closed"):
        stream.get(1.0)


def test_async_iteration_gets_events_pushed_from_another_thread() -> None:
    stream = EventStream(frozenset(KINDS))

    async def read() -> list[str]:
        kinds = []
        async for event in stream:
            kinds.append(event.kind)
            if len(kinds) == 2:
                stream.close()
        return kinds

    def feed() -> None:
        stream.push(_ev("ARRIVED"))
        stream.push(_ev("LEFT"))

    threading.Thread(target=feed).start()
    assert asyncio.run(asyncio.wait_for(read(), 10)) == ["ARRIVED", "LEFT"]


# --- a real people service ---------------------------------------------------------------


@pytest.mark.integration
def test_a_person_arriving_now_is_a_live_event(spawn: Callable[..., Process], probe: Node,
                                              bot_factory: Callable[..., Bot],
                                              tmp_path: Path) -> None:
    start_people(spawn, probe, tmp_path)
    bot = bot_factory()
    assert bot.people.now() == ()
    got: list[Event] = []
    done = threading.Event()
    bot.on("ARRIVED", lambda e: (got.append(e), done.set()))
    stream = bot.events("ARRIVED")
    with ThreadPoolExecutor(1) as pool:
        waiting = pool.submit(bot.wait_for, "ARRIVED", None, 30)
        # The person must arrive after wait_for subscribed, or it would be replayed.
        retry_until(lambda: len(bot.people._streams) == 3, 10, what="wait_for subscribed")
        stamp = Visitor(probe).presence(True, 1.0)
        event = waiting.result(60)
    assert (event.replayed, event.stamp_ns, event.person.id) == (False, stamp, 1)
    assert stream.get(30).stamp_ns == stamp
    assert done.wait(30) and got[0].stamp_ns == stamp


@pytest.mark.integration
def test_a_bot_connected_later_gets_the_arrival_replayed(spawn: Callable[..., Process],
                                                        probe: Node,
                                                        bot_factory: Callable[..., Bot],
                                                        tmp_path: Path) -> None:
    start_people(spawn, probe, tmp_path)
    events = Collector[m.PersonEvent](probe, keys.PEOPLE_EVENTS)
    stamp = Visitor(probe).presence(True, 2.0)
    events.wait_for(lambda e: e.kind == "ARRIVED", 30, "ARRIVED")
    bot = bot_factory()
    event = bot.wait_for("ARRIVED", lambda e: e.person.id == 1, timeout=30)
    assert event.replayed and event.stamp_ns == stamp < time.time_ns()
    assert event.person.arrived_ns == stamp and event.person.zone == "SOCIAL"
    assert [p.id for p in bot.people.now()] == [1]
    with pytest.raises(TimedOut, match=r"no LEFT event within 0\.3 s"):
        bot.wait_for("LEFT", timeout=0.3)


@pytest.mark.integration
def test_dwell_and_distance_events_from_the_real_people_service(
        spawn: Callable[..., Process], probe: Node, bot_factory: Callable[..., Bot],
        tmp_path: Path) -> None:
    """`bot.people.dwell` and `within` through the real people service: the dwell
    counts from the arrival, the distance line fires once each way."""
    start_people(spawn, probe, tmp_path)
    bot = bot_factory()
    dwell, line = bot.people.dwell(1.0), bot.people.within(1.5, margin_m=0.2)
    visitor = Visitor(probe)
    stamp = visitor.presence(True, 2.5)
    event = dwell.get(30)
    assert (event.kind, event.person.id, event.stamp_ns) == ("DWELL", 1, stamp + 10**9)
    assert time.time_ns() >= event.stamp_ns
    for metres in (2.0, 1.4, 1.6, 1.45, 1.8):  # a face's distances, 1.4 m -> near
        visitor.face(metres)
        if metres == 1.4:
            assert line.get(30).kind == "NEAR"
    assert line.get(30).kind == "FAR"
    with pytest.raises(TimedOut):
        line.get(0.5)  # 1.6 and 1.45 were inside the margin: nothing more


def test_poll_takes_a_waiting_event_and_never_waits() -> None:
    stream = EventStream(frozenset(KINDS))
    assert stream.poll() is None
    event = Event("LEFT", Person(id=1, zone="SOCIAL", engagement="GONE"), 5)
    stream.push(event)
    assert stream.poll() is event and stream.poll() is None


@pytest.mark.integration
def test_the_person_the_robot_attends_to(spawn: Callable[..., Process], probe: Node,
                                         bot_factory: Callable[..., Bot],
                                         controller: Callable[[], Process],
                                         tmp_path: Path) -> None:
    bot = bot_factory()
    with pytest.raises(NoService, match="controller"):
        bot.people.attended(timeout=0.5)  # nobody decides yet
    start_people(spawn, probe, tmp_path)
    controller()
    assert bot.people.attended() is None  # asleep: nobody attended
    Visitor(probe).presence(True, 1.0)
    retry_until(lambda: bot.people.attended() is not None, 30, 0.1, "attended")
    attended = bot.people.attended()
    assert attended is not None and attended.id == 1
