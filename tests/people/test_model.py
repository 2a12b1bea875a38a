"""The people model, scenario by scenario: inputs with their times in, the
events (kind, person, what changed, when) out, compared in full."""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from buddybot.people.model import (
    Arrived,
    Engagement,
    EngagementChanged,
    FaceSeen,
    Input,
    Left,
    PeopleModel,
    PersonEvent,
    RadarSeen,
    Sensor,
    Tick,
    ZoneChanged,
)
from buddybot.people.settings import PeopleSettings
from buddybot.people.zones import Zone
from tests.properties import examples

SETTINGS = PeopleSettings(
    intimate_limit_m=0.45, personal_limit_m=1.2, social_limit_m=3.6, zone_margin_m=0.1,
    face_timeout_s=0.5, engage_dwell_s=1.0, look_away_s=1.0, disengage_hold_s=2.0,
    absence_hold_s=3.0)

Row = tuple[float, int, str, str]
"""(seconds, person id, kind, what): a readable event."""


def ns(t: float) -> int:
    return round(t * 1e9)


def radar(t: float, distance_m: float = 2.0) -> RadarSeen:
    return RadarSeen(ns(t), True, distance_m)


def radar_out(t: float) -> RadarSeen:
    return RadarSeen(ns(t), False, 4.0)


def face(t: float, distance_m: float = 2.0) -> FaceSeen:
    return FaceSeen(ns(t), distance_m, 0.1, -0.05)


def faces(start: float, end: float, distance_m: float = 2.0) -> Iterator[FaceSeen]:
    """A face every 0.1 s from `start` to `end`, both included."""
    for i in range(round((end - start) * 10) + 1):
        yield face(start + i / 10, distance_m)


def tick(t: float) -> Tick:
    return Tick(ns(t))


def row(e: PersonEvent) -> Row:
    t = e.stamp_ns / 1e9
    match e:
        case Arrived():
            return (t, e.person_id, "arrived", e.person.zone.name)
        case ZoneChanged():
            return (t, e.person_id, "zone", f"{e.zone_from.name}->{e.zone_to.name}")
        case EngagementChanged():
            return (t, e.person_id, "engagement",
                    f"{e.engagement_from.name}->{e.engagement_to.name}")
        case Left():
            return (t, e.person_id, "left", "")


def run(inputs: Iterable[Input | Iterable[Input]],
        model: PeopleModel | None = None) -> list[Row]:
    m = PeopleModel(SETTINGS) if model is None else model
    out: list[Row] = []
    for item in inputs:
        for one in [item] if isinstance(item, Input) else item:
            out += [row(e) for e in m.step(one)]
    return out


ENGAGE = [(0.5, 1, "engagement", "NONE->ENGAGING"), (1.5, 1, "engagement", "ENGAGING->ENGAGED")]

SCENARIOS: dict[str, tuple[list[Input | Iterable[Input]], list[Row]]] = {
    "approach": (
        [radar(0.0, 4.0), faces(0.5, 1.0, 3.7), faces(1.1, 1.5, 3.0), faces(1.6, 2.0, 1.0),
         faces(2.1, 2.5, 0.3)],
        [(0.0, 1, "arrived", "PUBLIC"), (1.1, 1, "zone", "PUBLIC->SOCIAL"),
         (1.1, 1, "engagement", "NONE->ENGAGING"), (1.6, 1, "zone", "SOCIAL->PERSONAL"),
         (2.1, 1, "engagement", "ENGAGING->ENGAGED"),
         (2.1, 1, "zone", "PERSONAL->INTIMATE")]),
    "engage after the dwell": (
        [radar(0.0), faces(0.5, 3.0)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE]),
    "a glance shorter than the dwell engages nobody": (
        [radar(0.0), faces(0.5, 1.0), tick(5.0)],
        [(0.0, 1, "arrived", "SOCIAL"), (0.5, 1, "engagement", "NONE->ENGAGING"),
         (2.5, 1, "engagement", "ENGAGING->NONE")]),
    "a face only beyond the social zone engages nobody": (
        [radar(0.0, 2.0), faces(0.5, 4.0, 4.5), tick(6.0)],
        [(0.0, 1, "arrived", "SOCIAL"), (0.5, 1, "zone", "SOCIAL->PUBLIC")]),
    "zones change with hysteresis": (
        [face(0.0, 1.15), face(0.1, 1.29), face(0.2, 1.31), face(0.3, 1.11), face(0.4, 1.09),
         face(0.5, 0.5), face(0.6, 0.36), face(0.7, 0.3), face(0.8, 0.54), face(0.9, 0.56)],
        [(0.0, 1, "arrived", "PERSONAL"), (0.0, 1, "engagement", "NONE->ENGAGING"),
         (0.2, 1, "zone", "PERSONAL->SOCIAL"), (0.4, 1, "zone", "SOCIAL->PERSONAL"),
         (0.7, 1, "zone", "PERSONAL->INTIMATE"), (0.9, 1, "zone", "INTIMATE->PERSONAL")]),
    "a jump crosses every limit by the margin": (
        [face(0.0, 0.3), face(0.1, 3.65), face(0.2, 3.75)],
        [(0.0, 1, "arrived", "INTIMATE"), (0.0, 1, "engagement", "NONE->ENGAGING"),
         (0.1, 1, "zone", "INTIMATE->SOCIAL"), (0.2, 1, "zone", "SOCIAL->PUBLIC")]),
    "a face missed for less than face_timeout_s changes nothing": (
        [radar(0.0), faces(0.5, 2.0), faces(2.45, 4.0), tick(4.2)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE]),
    "a face lost for less than look_away_s changes nothing": (
        [radar(0.0), faces(0.5, 2.0), faces(3.4, 5.0), tick(5.2)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE]),
    "looking away: disengaging, then engaged again after the dwell": (
        [radar(0.0), faces(0.5, 2.0), faces(4.0, 6.0), tick(6.2)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE,
         (3.5, 1, "engagement", "ENGAGED->DISENGAGING"),
         (5.0, 1, "engagement", "DISENGAGING->ENGAGED")]),
    "a glance back shorter than the dwell does not re-engage": (
        [radar(0.0), faces(0.5, 2.0), faces(4.0, 4.5), tick(10.0)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE,
         (3.5, 1, "engagement", "ENGAGED->DISENGAGING"),
         (5.5, 1, "engagement", "DISENGAGING->NONE")]),
    "a face lost for disengage_hold_s ends the engagement": (
        [radar(0.0), faces(0.5, 2.0), tick(10.0)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE,
         (3.5, 1, "engagement", "ENGAGED->DISENGAGING"),
         (5.5, 1, "engagement", "DISENGAGING->NONE")]),
    "stepping out of the social zone disengages": (
        [radar(0.0), faces(0.5, 2.0, 2.0), faces(2.1, 5.0, 3.8), tick(6.0)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE, (2.1, 1, "zone", "SOCIAL->PUBLIC"),
         (3.1, 1, "engagement", "ENGAGED->DISENGAGING"),
         (5.1, 1, "engagement", "DISENGAGING->NONE")]),
    "radar lost briefly: the same person": (
        [radar(0.0), radar_out(2.0), radar(4.5), tick(10.0)],
        [(0.0, 1, "arrived", "SOCIAL")]),
    "face and radar taking turns: the same person": (
        [radar(0.0), radar_out(1.0), faces(2.0, 2.5), radar(5.0), radar_out(6.0),
         faces(8.0, 8.0), tick(8.4)],
        [(0.0, 1, "arrived", "SOCIAL"), (2.0, 1, "engagement", "NONE->ENGAGING"),
         (4.0, 1, "engagement", "ENGAGING->NONE"), (8.0, 1, "engagement", "NONE->ENGAGING")]),
    "leave": (
        [radar(0.0), radar_out(2.0), tick(20.0)],
        [(0.0, 1, "arrived", "SOCIAL"), (5.0, 1, "engagement", "NONE->GONE"),
         (5.0, 1, "left", "")]),
    "an engaged person leaves: disengaging, none, gone": (
        [radar(0.0), faces(0.5, 2.0), radar_out(3.0), tick(20.0)],
        [(0.0, 1, "arrived", "SOCIAL"), *ENGAGE,
         (3.5, 1, "engagement", "ENGAGED->DISENGAGING"),
         (5.5, 1, "engagement", "DISENGAGING->NONE"),
         (6.0, 1, "engagement", "NONE->GONE"), (6.0, 1, "left", "")]),
    "a return after absence_hold_s is a new person": (
        [radar(0.0), radar_out(1.0), radar(3.9), radar_out(4.5), tick(20.0), radar(30.0),
         faces(30.2, 30.2)],
        [(0.0, 1, "arrived", "SOCIAL"), (7.5, 1, "engagement", "NONE->GONE"),
         (7.5, 1, "left", ""), (30.0, 2, "arrived", "SOCIAL"),
         (30.2, 2, "engagement", "NONE->ENGAGING")]),
    "the same return, timed by the data alone (no tick)": (
        [radar(0.0), radar_out(1.0), radar(3.9), radar_out(4.5), radar(30.0)],
        [(0.0, 1, "arrived", "SOCIAL"), (7.5, 1, "engagement", "NONE->GONE"),
         (7.5, 1, "left", ""), (30.0, 2, "arrived", "SOCIAL")]),
    "a person present at the start arrived in the past": (
        [tick(100.0), radar(90.0, 1.0), tick(100.5)],
        [(90.0, 1, "arrived", "PERSONAL")]),
    "nobody in range is nobody": (
        [radar_out(0.0), tick(1.0), radar_out(2.0), tick(30.0)],
        []),
}


@pytest.mark.parametrize("name", SCENARIOS)
def test_scenario(name: str) -> None:
    inputs, expected = SCENARIOS[name]
    assert run(inputs) == expected


def test_absence_hold_s_is_the_limit_of_one_visit() -> None:
    """Missed exactly `absence_hold_s`: gone, and the return is someone new."""
    assert run([radar(0.0), radar_out(1.0), radar(4.0)]) == [
        (0.0, 1, "arrived", "SOCIAL"), (4.0, 1, "engagement", "NONE->GONE"),
        (4.0, 1, "left", ""), (4.0, 2, "arrived", "SOCIAL")]


def test_leaving_while_disengaging_goes_straight_to_gone() -> None:
    m = PeopleModel(msgspec.structs.replace(SETTINGS, disengage_hold_s=10.0))
    # Gone `absence_hold_s` after the later last sighting: the radar's at 2.2.
    assert run([radar(0.0), faces(0.5, 2.0), radar_out(2.2), tick(5.1), tick(5.2)], m) == [
        (0.0, 1, "arrived", "SOCIAL"), *ENGAGE, (3.5, 1, "engagement", "ENGAGED->DISENGAGING"),
        (5.2, 1, "engagement", "DISENGAGING->GONE"), (5.2, 1, "left", "")]


def test_the_distance_is_the_cameras_while_it_sees_the_face() -> None:
    m = PeopleModel(SETTINGS)
    run([radar(0.0, 2.0)], m)
    assert m.state()[0].distance_m == 2.0 and m.state()[0].seen_by is Sensor.RADAR
    run([face(0.1, 1.5)], m)
    assert m.state()[0].distance_m == 1.5 and m.state()[0].seen_by is Sensor.BOTH
    run([radar(0.2, 2.5)], m)  # the radar's own distance: the camera's is better
    assert m.state()[0].distance_m == 1.5
    run([tick(0.7)], m)  # the camera lost them: its last distance stays
    assert m.state()[0].distance_m == 1.5 and m.state()[0].seen_by is Sensor.RADAR
    run([radar(0.8, 2.5)], m)  # then the newest measurement
    assert m.state()[0].distance_m == 2.5


def test_the_state_of_a_person() -> None:
    m = PeopleModel(SETTINGS)
    run([tick(10.0), radar(9.0, 1.0), faces(10.1, 11.5, 1.0)], m)
    (p,) = m.state()
    assert (p.id, p.arrived_ns, p.zone, p.zone_since_ns) == (1, ns(9.0), Zone.PERSONAL, ns(9.0))
    assert (p.engagement, p.engagement_since_ns) == (Engagement.ENGAGED, ns(11.1))
    assert (p.seen_by, p.yaw_rad, p.pitch_rad, p.name) == (Sensor.BOTH, 0.1, -0.05, None)
    run([radar_out(12.0), tick(12.5)], m)
    assert m.state()[0].seen_by is Sensor.NONE  # missed, not yet gone
    run([tick(15.5)], m)
    assert m.state() == ()


def test_left_carries_the_final_state() -> None:
    m = PeopleModel(SETTINGS)
    inputs: list[Input] = [radar(0.0, 1.0), radar_out(1.0), tick(9.0)]
    events = [e for i in inputs for e in m.step(i)]
    assert isinstance(events[-1], Left)
    assert events[-1].person.engagement is Engagement.GONE
    assert events[-1].person.seen_by is Sensor.NONE


def test_a_sample_older_than_the_last_of_its_sensor_is_ignored() -> None:
    m = PeopleModel(SETTINGS)
    assert run([radar(5.0), radar_out(4.0), tick(20.0)], m) == [(5.0, 1, "arrived", "SOCIAL")]
    assert run([face(21.0, 1.0), face(20.9, 3.0)], m) == [
        (21.0, 1, "zone", "SOCIAL->PERSONAL"), (21.0, 1, "engagement", "NONE->ENGAGING")]
    assert m.state()[0].distance_m == 1.0


def test_a_face_older_than_face_timeout_s_shows_nobody() -> None:
    assert run([tick(10.0), face(9.0)]) == []


@pytest.mark.parametrize("bad", [
    lambda: RadarSeen(-1, True, 1.0),
    lambda: RadarSeen(0, True, float("nan")),
    lambda: RadarSeen(0, True, -0.1),
    lambda: FaceSeen(0, float("inf"), 0.0, 0.0),
    lambda: FaceSeen(0, 1.0, float("nan"), 0.0),
])
def test_a_sample_outside_its_range_is_refused(bad: object) -> None:
    with pytest.raises(ValueError):
        bad()  # type: ignore[operator]


@settings(max_examples=examples(100))
@given(st.lists(st.floats(0.1, 1.4), min_size=60, max_size=200))
def test_a_person_standing_still_while_the_face_is_missed_now_and_then_engages_once(
        gaps: list[float]) -> None:
    """Faces missed for up to 1.4 s (the face times out after 0.5 s, the look-away
    hold is 1 s) over a minute or more: one engagement, never undone."""
    inputs: list[Input] = [radar(0.0, 1.0)]
    t = 0.5
    for gap in gaps:
        inputs.append(face(t, 1.0))
        t += gap
    rows = [r for r in run([*inputs, tick(t)]) if r[2] == "engagement"]
    assert [what for _t, _id, _kind, what in rows] == ["NONE->ENGAGING", "ENGAGING->ENGAGED"]
    assert rows[0][0] == 0.5


def test_each_persons_stamps_never_go_back_even_when_a_hold_ends_after_the_input() -> None:
    """A face stamped before the look-away deadline arrives after a tick past it."""
    model = PeopleModel(SETTINGS)
    events = [e for item in [radar(0.0), faces(0.5, 2.0), tick(3.6), face(3.55), face(3.7),
                             tick(10.0)]
              for one in ([item] if isinstance(item, Input) else item)
              for e in model.step(one)]
    stamps = [e.stamp_ns for e in events if e.person_id == 1]
    assert stamps == sorted(stamps), [row(e) for e in events]
