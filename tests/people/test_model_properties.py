"""Property-based tests of the people model with a fake clock.

A hypothesis state machine drives a radar (in or out of range, any
distance), a camera (single faces or a stream at 10 frames/s) and time in
any order; after every step the events so far must keep these rules:

* ids are never reused, and a person's events run ARRIVED first, LEFT last,
  nothing after LEFT, stamps never going back (the inputs come in order);
* at most one person is present, and the present one is the one arrived
  and not yet left;
* a zone changes only when the distance is past the old zone's limit by
  the margin, to the zone `zone_after` gives;
* engagement moves only along the diagram's edges, ENGAGED comes after
  `engage_dwell_s` of ENGAGING (or back from DISENGAGING), NONE after
  `disengage_hold_s` of DISENGAGING, GONE right before LEFT;
* LEFT comes exactly `absence_hold_s` after both sensors lost the person;
* at the end, with both sensors stopped for `absence_hold_s`, everyone seen
  has left.

Two more properties generate whole timelines: sightings separated by gaps
shorter than the absence hold are one person (longer gaps: one new person
each), and how often `Tick` comes changes no event.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

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
    Tick,
    ZoneChanged,
)
from buddybot.people.zones import Zone, zone_after
from tests.properties import examples

from .test_model import SETTINGS, ns

TIMEOUT = ns(SETTINGS.face_timeout_s)
ABSENCE = ns(SETTINGS.absence_hold_s)
FRAME = ns(0.1)
E = Engagement
EDGES = {
    (E.NONE, E.ENGAGING), (E.ENGAGING, E.ENGAGED), (E.ENGAGING, E.NONE),
    (E.ENGAGED, E.DISENGAGING), (E.DISENGAGING, E.ENGAGED), (E.DISENGAGING, E.NONE),
    *((e, E.GONE) for e in (E.NONE, E.ENGAGING, E.ENGAGED, E.DISENGAGING)),
}
"""Every engagement change the model may make."""
LIMITS = (SETTINGS.intimate_limit_m, SETTINGS.personal_limit_m, SETTINGS.social_limit_m)
distances = st.sampled_from([0.3, 0.44, 0.5, 1.0, 1.15, 1.25, 1.35, 2.0, 3.55, 3.65, 3.75, 5.0])


def crossed_by_the_margin(zone_from: Zone, zone_to: Zone, distance_m: float) -> bool:
    """Whether `distance_m` lies past the old zone's limit on the new zone's side
    by the margin."""
    margin = SETTINGS.zone_margin_m
    if zone_to > zone_from:
        return distance_m - margin >= LIMITS[zone_from]
    return distance_m + margin < LIMITS[zone_from - 1]


@dataclass
class Log:
    """Every event of a run, and the rules they must keep."""

    events: list[PersonEvent] = field(default_factory=list)
    left_expected: dict[int, int] = field(default_factory=dict)
    """Person id -> the stamp their LEFT must have."""

    def problems(self) -> list[str]:
        found: list[str] = []
        by_person: dict[int, list[PersonEvent]] = {}
        arrived: list[int] = []
        for e in self.events:
            mine = by_person.setdefault(e.person_id, [])
            if isinstance(e, Arrived):
                if mine or (arrived and e.person_id <= arrived[-1]):
                    found.append(f"id {e.person_id} reused")
                arrived.append(e.person_id)
            elif not mine:
                found.append(f"{e} before the person arrived")
            elif isinstance(mine[-1], Left):
                found.append(f"{e} after the person left")
            elif e.stamp_ns < mine[-1].stamp_ns:
                found.append(f"{e} stamped before {mine[-1]}")
            mine.append(e)
        for pid, mine in by_person.items():
            found += self.person_problems(pid, mine)
        return found

    def person_problems(self, pid: int, mine: list[PersonEvent]) -> list[str]:
        found: list[str] = []
        engagement, since = E.NONE, mine[0].stamp_ns
        for i, e in enumerate(mine):
            if isinstance(e, ZoneChanged):
                if e.zone_to is e.zone_from or not crossed_by_the_margin(
                        e.zone_from, e.zone_to, e.distance_m):
                    found.append(f"{e}: not past the limit by the margin")
                if zone_after(e.zone_from, e.distance_m, SETTINGS) is not e.zone_to:
                    found.append(f"{e}: not the zone of the distance")
            elif isinstance(e, EngagementChanged):
                step = (e.engagement_from, e.engagement_to)
                if e.engagement_from is not engagement or step not in EDGES:
                    found.append(f"{e}: not an edge from {engagement.name}")
                if step == (E.ENGAGING, E.ENGAGED) and \
                        e.stamp_ns - since < ns(SETTINGS.engage_dwell_s):
                    found.append(f"{e}: engaged before the dwell")
                if step == (E.DISENGAGING, E.NONE) and \
                        e.stamp_ns - since < ns(SETTINGS.disengage_hold_s):
                    found.append(f"{e}: disengaged before the hold")
                if e.engagement_to is E.GONE and not (
                        i + 1 < len(mine) and isinstance(mine[i + 1], Left)):
                    found.append(f"{e}: GONE not followed by LEFT")
                engagement, since = e.engagement_to, e.stamp_ns
            elif isinstance(e, Left):
                if engagement is not E.GONE:
                    found.append(f"{e}: LEFT while {engagement.name}")
                if e.stamp_ns != self.left_expected.get(pid):
                    found.append(f"{e}: expected at {self.left_expected.get(pid)}")
        return found


class World(RuleBasedStateMachine):
    """A radar, a camera and time, in any order; the model under test."""

    def __init__(self) -> None:
        super().__init__()
        self.t = ns(1000.0)
        self.model = PeopleModel(SETTINGS)
        self.log = Log()
        self.radar_in = False
        self.radar_lost = -1  # when the radar last went out of range
        self.last_face = -ns(1000.0)

    def feed(self, item: Input) -> None:
        for e in self.model.step(item):
            if isinstance(e, Left):
                # The absence counts from the later of the sensors' last sightings.
                lost = max(self.radar_lost, self.last_face)
                self.log.left_expected[e.person_id] = lost + ABSENCE
            self.log.events.append(e)

    @rule(dt=st.sampled_from([0.05, 0.1, 0.3, 0.6, 1.0, 2.0, 2.9, 3.1, 8.0]),
          watching=st.booleans(), distance=distances, ticking=st.booleans())
    def wait(self, dt: float, watching: bool, distance: float, ticking: bool) -> None:
        """Time passes in frames of 0.1 s: a face in each (`watching`), a tick in
        each (`ticking`), or neither."""
        end = self.t + ns(dt)
        while self.t < end:
            self.t = min(end, self.t + FRAME)
            if watching:
                self.face(distance)
            if ticking:
                self.feed(Tick(self.t))

    @rule(in_range=st.booleans(), distance=distances)
    def radar(self, in_range: bool, distance: float) -> None:
        self.feed(RadarSeen(self.t, in_range, distance))  # LEFT before it: the old losses
        if self.radar_in and not in_range:
            self.radar_lost = self.t
        self.radar_in = in_range

    @rule(distance=distances)
    def face(self, distance: float) -> None:
        self.feed(FaceSeen(self.t, distance, 0.0, 0.0))
        self.last_face = self.t

    @rule()
    def tick(self) -> None:
        self.feed(Tick(self.t))

    @invariant()
    def the_events_keep_the_rules(self) -> None:
        problems = self.log.problems()
        assert not problems, problems

    @invariant()
    def at_most_the_one_person_arrived_and_not_left(self) -> None:
        present = self.model.state()
        assert len(present) <= 1
        last = self.log.events[-1] if self.log.events else None
        expected = () if last is None or isinstance(last, Left) else (last.person_id,)
        assert tuple(p.id for p in present) == expected

    def teardown(self) -> None:
        """Both sensors stop: after `absence_hold_s` everyone seen has left."""
        self.radar(False, 5.0)
        self.t = max(self.t, self.last_face + TIMEOUT) + ABSENCE
        self.feed(Tick(self.t))
        assert self.model.state() == ()
        arrived = {e.person_id for e in self.log.events if isinstance(e, Arrived)}
        left = {e.person_id for e in self.log.events if isinstance(e, Left)}
        assert arrived == left
        problems = self.log.problems()
        assert not problems, problems


World.TestCase.settings = settings(max_examples=examples(200), stateful_step_count=40)
TestPeopleModelProperties = World.TestCase


# --- whole timelines ---------------------------------------------------------------------

SOURCES = st.sampled_from(["radar", "camera", "both"])


Sample = RadarSeen | FaceSeen


def sighting(start: int, source: str, length: int, distance: float) -> list[Sample]:
    """Someone shown by `source` from `start` for `length` ns (faces at 10/s)."""
    inputs: list[Sample] = []
    if source in ("radar", "both"):
        inputs.append(RadarSeen(start, True, distance))
    if source in ("camera", "both"):
        inputs += [FaceSeen(start + k * FRAME, distance, 0.0, 0.0)
                   for k in range(length // FRAME + 1)]
    if source in ("radar", "both"):
        inputs.append(RadarSeen(start + length, False, distance))
    return sorted(inputs, key=lambda i: i.stamp_ns)


@st.composite
def timelines(draw: st.DrawFn) -> tuple[list[Sample], int]:
    """Sightings with gaps between them, and how many of the gaps are long enough
    (with both sensors lost for at least `absence_hold_s`) to end a visit."""
    inputs: list[Sample] = []
    t, long_gaps = ns(10.0), 0
    for n in range(draw(st.integers(1, 6))):
        if n:
            # A gap is measured from the sighting's last sample, as the absence
            # hold is (the face timeout and the radar's own hold overlap it).
            if draw(st.booleans()):
                gap = draw(st.integers(ns(0.01), ABSENCE - 1))
            else:
                gap = draw(st.integers(ABSENCE, ABSENCE + ns(20.0)))
                long_gaps += 1
            t += gap
        length = draw(st.integers(0, ns(4.0)))
        inputs += sighting(t, draw(SOURCES), length, draw(distances))
        t = inputs[-1].stamp_ns
    return inputs, long_gaps


def run(inputs: list[Input]) -> list[PersonEvent]:
    model = PeopleModel(SETTINGS)
    return [e for i in inputs for e in model.step(i)]


@settings(max_examples=examples(300))
@given(timelines())
def test_a_gap_shorter_than_the_absence_hold_is_the_same_person(
        timeline: tuple[list[Sample], int]) -> None:
    inputs, long_gaps = timeline
    events = run([*inputs, Tick(inputs[-1].stamp_ns + TIMEOUT + ABSENCE)])
    assert [e.person_id for e in events if isinstance(e, Arrived)] == \
        list(range(1, long_gaps + 2))
    assert [e.person_id for e in events if isinstance(e, Left)] == \
        list(range(1, long_gaps + 2))


@settings(max_examples=examples(300))
@given(timelines(), st.lists(st.integers(0, ns(40.0)), max_size=30), st.data())
def test_how_often_ticks_come_changes_no_event(
        timeline: tuple[list[Sample], int], offsets: list[int], data: st.DataObject) -> None:
    """Ticks anywhere between the samples (never ahead of the next one) leave the
    events, their order and their stamps as they are."""
    inputs, _ = timeline
    start, end = inputs[0].stamp_ns, inputs[-1].stamp_ns + TIMEOUT + ABSENCE
    ticks: list[Input] = [Tick(start + o) for o in offsets if start + o <= end]
    if data.draw(st.booleans()):  # ticks at exactly the samples' stamps too
        ticks += [Tick(i.stamp_ns) for i in inputs]
    # A tick goes before a sample of the same stamp or after: either is in order.
    ticks_first = data.draw(st.booleans())
    ticked = sorted([*inputs, *ticks], key=lambda i: (
        i.now_ns if isinstance(i, Tick) else i.stamp_ns, isinstance(i, Tick) != ticks_first))
    assert run([*ticked, Tick(end)]) == run([*inputs, Tick(end)])
