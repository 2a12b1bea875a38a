"""`people/state`'s pacing, pure: news goes out at once, a change only of where
people are at most every period, and a held state goes out later with its own stamp."""

from __future__ import annotations

import dataclasses
import itertools

from buddybot.people.model import Engagement, Person, Sensor
from buddybot.people.pacing import WHERE, StatePacer, moved_only
from buddybot.people.zones import Zone

PERIOD = 0.1


def person(pid: int = 1, distance: float = 1.5, **fields: object) -> Person:
    base = Person(id=pid, distance_m=distance, zone=Zone.PERSONAL, seen_by=Sensor.CAMERA,
                  zone_since_ns=1, arrived_ns=1, engagement=Engagement.ENGAGING,
                  engagement_since_ns=1, yaw_rad=0.1, pitch_rad=0.0)
    return dataclasses.replace(base, **fields)  # type: ignore[arg-type]


def test_where_names_fields_of_a_person() -> None:
    names = {f.name for f in dataclasses.fields(Person)}
    assert names > WHERE


def test_only_the_position_fields_count_as_moving() -> None:
    a = (person(),)
    assert moved_only((person(distance=1.4, yaw_rad=0.2, pitch_rad=0.1, bearing_rad=0.3),), a)
    for news in ({"zone": Zone.SOCIAL}, {"engagement": Engagement.ENGAGED},
                 {"seen_by": Sensor.BOTH}, {"name": "Ada"}, {"id": 2}):
        assert not moved_only((person(**news),), a), news
    assert not moved_only((person(), person(2)), a)
    assert not moved_only((), a)


def test_the_first_state_and_news_go_out_at_once() -> None:
    pacer = StatePacer()
    assert pacer.offer((), 10, now_s=0.0, period_s=PERIOD) == 10
    assert pacer.offer((person(),), 11, now_s=0.001, period_s=PERIOD) == 11
    engaged = (person(engagement=Engagement.ENGAGED),)
    assert pacer.offer(engaged, 12, now_s=0.002, period_s=PERIOD) == 12
    assert pacer.offer(engaged, 13, now_s=0.003, period_s=PERIOD) is None  # unchanged


def test_moving_goes_out_at_most_once_a_period_with_the_stamp_of_its_input() -> None:
    pacer = StatePacer()
    assert pacer.offer((person(distance=2.0),), 0, now_s=0.0, period_s=PERIOD) == 0
    sent = []
    for frame in range(1, 31):  # a face at 30/s for a second, coming nearer
        now = frame / 30
        stamp = pacer.offer((person(distance=2.0 - frame / 100),), frame, now, PERIOD)
        if stamp is not None:
            sent.append(stamp)
    assert 7 <= len(sent) <= 10  # a period ends between two frames
    assert all(b - a >= 3 for a, b in itertools.pairwise(sent))
    # The last one is held; a tick after the period sends it with its own stamp.
    assert pacer.holding
    last = (person(distance=2.0 - 30 / 100),)
    assert pacer.offer(last, 999, now_s=1.0 + PERIOD, period_s=PERIOD) == 30
    assert not pacer.holding
    assert pacer.offer(last, 1000, now_s=1.5, period_s=PERIOD) is None


def test_news_during_a_period_goes_out_at_once_and_drops_what_was_held() -> None:
    pacer = StatePacer()
    pacer.offer((person(),), 0, now_s=0.0, period_s=PERIOD)
    assert pacer.offer((person(distance=1.4),), 1, now_s=0.01, period_s=PERIOD) is None
    news = (person(distance=1.3, engagement=Engagement.ENGAGED),)
    assert pacer.offer(news, 2, now_s=0.02, period_s=PERIOD) == 2
    assert not pacer.holding


def test_moving_back_to_what_was_published_sends_nothing() -> None:
    pacer = StatePacer()
    pacer.offer((person(),), 0, now_s=0.0, period_s=PERIOD)
    assert pacer.offer((person(distance=1.4),), 1, now_s=0.01, period_s=PERIOD) is None
    assert pacer.offer((person(),), 2, now_s=0.5, period_s=PERIOD) is None
    assert not pacer.holding


def test_a_period_of_zero_sends_every_change() -> None:
    pacer = StatePacer()
    pacer.offer((person(),), 0, now_s=0.0, period_s=0.0)
    stamps = [pacer.offer((person(distance=1.5 - i / 100),), i, now_s=0.0, period_s=0.0)
              for i in range(1, 6)]
    assert stamps == [1, 2, 3, 4, 5]
