"""The whole simulated robot (`up --sim --scenario`) against the world's truth.

What a person in front of the robot would see, checked on the bus while
the real services run on one simulated world: greeted once per visit,
goodbye after they left, eyes asleep when nobody is there, the gaze on
the person, no greeting for someone who only walks past. `sim/world` says
what really happened, so each check is against the truth, not a script.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import available_services
from buddybot.tools.testing import Collector, retry_until
from tests.sim import SCENARIOS
from tests.system.robot import Arrivals, robot_on, sounds

pytestmark = [pytest.mark.integration, pytest.mark.robot]


NEAR: frozenset[m.Zone] = frozenset({"INTIMATE", "PERSONAL", "SOCIAL"})
ASLEEP: frozenset[m.EngagementPhase] = frozenset({"idle", "drowsy"})


FACE_GAP_S = 0.8
"""Below `[people] look_away_s` (1 s): a face stream without a longer gap shows a
person standing in view to the people service the whole time."""


def one_truth_problems(people: Arrivals, state: Arrivals, events: list[m.PersonEvent],
                       truth: list[m.SimWorld], faces: list[int], since_ns: int,
                       until_ns: int, hop_s: float = 2.0) -> list[str]:
    """What breaks "one truth about who is there" between two stamps:
    - the robot asleep (controller phase idle or drowsy) `hop_s` after `people/state`
      showed a person in the social zone or nearer who was still there then;
    - more than one engagement change per 10 s while everyone in the world stands
      and the camera's face stream (`faces`: their stamps) has no gap of
      `FACE_GAP_S` (a detector starved by a busy machine misses a standing face,
      and the people service rightly sees them look away);
    - a greeting not within a person's visit in `people/events`, a farewell not
      within a visit that ended (as they walked away) or `hop_s` after its LEFT."""
    problems: list[str] = []
    for at, msg in zip(list(people.at), list(people.messages), strict=True):
        if not since_ns <= msg.stamp_ns <= until_ns:
            continue
        near = {p.id for p in msg.people if p.zone in NEAR}
        later = people.in_effect(at + hop_s)
        still = near & {p.id for p in later.people} if later is not None else set()
        now = state.in_effect(at + hop_s)
        if still and now is not None and now.phase in ASLEEP:
            problems.append(f"asleep ({now.phase}) with persons {sorted(still)} present")
    standing = [w.stamp_ns for w in truth if w.people and since_ns <= w.stamp_ns <= until_ns
                and all(abs(p.vx_mps) + abs(p.vy_mps) < 1e-3 for p in w.people)]
    start, end = (standing[0] + 2 * 10**9, standing[-1]) if standing else (0, 0)
    seen = sorted(f for f in faces if start <= f <= end)
    gaps = [b - a for a, b in zip([start, *seen], [*seen, end], strict=True)]
    if standing and max(gaps) > FACE_GAP_S * 1e9:
        print(f"engagement not checked: the face stream had a {max(gaps) / 1e9:.1f} s gap")
    elif standing:  # settled: 2 s after stopping
        for pid in sorted({e.person_id for e in events}):
            changes = [e for e in events if e.person_id == pid and start <= e.stamp_ns <= end
                       and e.kind == "ENGAGEMENT_CHANGED" and e.engagement != "GONE"]
            if len(changes) > max(1, (end - start) // 10**10):
                problems.append(f"person {pid}: {len(changes)} engagement changes in "
                                f"{(end - start) / 1e9:.0f} s of standing: "
                                f"{[e.engagement for e in changes]}")
    # A person whose ARRIVED came before the subscription was there from the start.
    visits = {e.person_id: (0, 2**63) for e in events}
    for e in events:
        start, end = visits[e.person_id]
        if e.kind == "ARRIVED":
            visits[e.person_id] = (e.stamp_ns, end)
        elif e.kind == "LEFT":
            visits[e.person_id] = (start, e.stamp_ns)
    left = [end for _start, end in visits.values() if end < 2**63]
    finals = [s for s in state.messages if since_ns <= s.stamp_ns <= until_ns]
    for t in sorted({s.last_greeting_ns for s in finals if s.last_greeting_ns}):
        if t >= since_ns and not any(a <= t <= b for a, b in visits.values()):
            problems.append(f"greeting at {t} outside every visit {visits}")
    for t in sorted({s.last_farewell_ns for s in finals if s.last_farewell_ns}):
        if t < since_ns:
            continue
        # As they walk away (before their LEFT) or just after it.
        if not any(came <= t <= gone + hop_s * 1e9 for came, gone in visits.values()
                   if gone < 2**63):
            problems.append(f"farewell at {t} not during or just after a visit that "
                            f"ended {left}")
    return problems


class Watch:
    """The world's truth, the people service's persons and events and the
    controller's state, from the start of a test."""

    def __init__(self, probe: Node) -> None:
        self.truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        self.state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        self.people = Arrivals(probe, keys.PEOPLE_STATE)
        self.states = Arrivals(probe, keys.CONTROLLER_STATE)
        self.events = Collector[m.PersonEvent](probe, keys.PEOPLE_EVENTS)
        self.faces = Collector[m.FacePosition](probe, keys.FACE, camera="front")

    def one_truth_problems(self, since_ns: int) -> list[str]:
        """`one_truth_problems` from `since_ns` to the controller's last state."""
        return one_truth_problems(self.people, self.states, self.events.messages,
                                  self.truth.messages,
                                  [f.stamp_ns for f in self.faces.messages], since_ns,
                                  self.state.messages[-1].stamp_ns)


def walked(states: list[m.PeopleState], since_ns: int, until_ns: int) -> list[str]:
    """The people service's persons from 1 s before `since_ns` to `until_ns`: what the
    controller's speeds were computed from (s after `since_ns`, id, distance, sensors)."""
    return [f"{(s.stamp_ns - since_ns) / 1e9:+.2f} " + " ".join(
                f"{p.id}:{p.distance_m:.2f}/{p.seen_by}" for p in s.people)
            for s in states if since_ns - 10**9 <= s.stamp_ns <= until_ns]


def test_a_visit_is_greeted_once_watched_said_goodbye_to_as_they_go_and_the_eyes_sleep(
        tmp_path: Path) -> None:
    """One whole lap of `visit`, from its start (lap 1: the robot is up and settled):
    greeted once; while they stand still the gaze keeps moving (never the same for
    5 s) yet rests on their face on average (within 3 degrees over 10 s), on the
    robot's left where they stand; the goodbye within 1.5 s of their turning to
    leave; one truth about who is there; asleep once they are gone. (One robot for
    all of it: each lap of the scenario is the same visit.)"""
    with robot_on(tmp_path, "visit") as probe:
        watch = Watch(probe)
        truth, state = watch.truth, watch.state
        gaze = Collector[m.EyesDirection](probe, keys.EYES_DIRECTION)
        people = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
        start = truth.wait_for(lambda w: w.t_s < 3 and w.lap >= 1, 120, "a new visit")
        lap = start.lap
        arrived = truth.wait_for(lambda w: w.lap == lap and any(
            p.in_camera for p in w.people), 60, "the visitor facing the camera")
        still = truth.wait_for(lambda w: w.lap == lap and w.t_s >= 8, 60, "standing")
        ten = truth.wait_for(lambda w: w.lap == lap and w.t_s >= 18, 60, "10 s later")

        def away(w: m.SimWorld) -> bool:
            return w.lap == lap and w.t_s > 20 and any(
                p.position.x * p.vx_mps + p.position.y * p.vy_mps > 0.1 for p in w.people)
        # The goodbye is seen coming from their face alone, as they step back facing the
        # robot (0.5 m in 1 s, beyond [controller] leave_speed_mps and leave_distance_m,
        # 0.3): an LD2410's presence carries no running distance once they turn away.
        turned = truth.wait_for(away, 60, "the visitor turning to leave")
        gone = truth.wait_for(lambda w: w.lap == lap and w.t_s > 30 and not w.people, 60,
                              "the visitor gone")
        retry_until(lambda: sounds(state.messages)[-1:] == ["farewell"], 60, 0.2, "goodbye")
        farewell = min(s.last_farewell_ns for s in state.messages
                       if s.last_farewell_ns and s.last_farewell_ns > turned.stamp_ns)
        assert (farewell - turned.stamp_ns) / 1e9 <= 1.5, (
            (farewell - turned.stamp_ns) / 1e9, walked(people.messages, turned.stamp_ns, farewell),
            [f"{(s.stamp_ns - turned.stamp_ns) / 1e9:+.2f} {s.phase} {s.sound} "
             f"greeted={s.greeted} pending={s.farewell_pending} waiting={s.waiting}"
             for s in state.messages if s.stamp_ns > turned.stamp_ns - 30 * 10**9])
        during = [s for s in state.messages if s.stamp_ns >= arrived.stamp_ns]
        assert sounds(during) == ["greeting", "farewell"], sounds(during)
        retry_until(lambda: state.messages[-1].expression == m.ExpressionAction.EYE_SLEEP,
                    60, 0.2, "asleep")
        # The gaze was on the visitor: to the robot's left, where they stood.
        looked = [d.yaw for d in gaze.messages if arrived.stamp_ns < d.stamp_ns < gone.stamp_ns]
        assert looked and sum(y > 0 for y in looked) > 0.8 * len(looked), looked[-20:]
        # Standing still for 10 s: the gaze moves at least every 5 s ...
        window = [d for d in gaze.messages if still.stamp_ns <= d.stamp_ns <= ten.stamp_ns]
        assert len(window) > 50
        held, since = 0.0, window[0]
        for d in window[1:]:
            if abs(d.yaw - since.yaw) > 1.0 or abs(d.pitch - since.pitch) > 1.0:
                since = d
            held = max(held, (d.stamp_ns - since.stamp_ns) / 1e9)
        assert held < 5.0, f"the gaze stood still for {held:.1f} s"
        # ... and is on their face on average.
        bearing = [math.degrees(w.people[0].bearing_rad) for w in truth.messages
                   if still.stamp_ns <= w.stamp_ns <= ten.stamp_ns and w.people]
        mean_yaw = sum(d.yaw for d in window) / len(window)
        assert abs(mean_yaw - sum(bearing) / len(bearing)) <= 3.0, (mean_yaw, bearing[:3])
        # One truth: the controller follows the people service's persons, holds nothing.
        assert watch.one_truth_problems(start.stamp_ns) == []


def test_two_people_one_truth_and_one_goodbye_each_visit(tmp_path: Path) -> None:
    """Two visitors overlapping: the robot stays awake while either is there, its
    engagement does not flap while they stand, and each sound belongs to a visit
    the people service saw."""
    with robot_on(tmp_path, str(SCENARIOS / "two_people_once.toml")) as probe:
        watch = Watch(probe)
        truth, state = watch.truth, watch.state
        start = truth.wait_for(timeout=60, what="the world").stamp_ns
        truth.wait_for(lambda w: len(w.people) == 2, 120, "both there")
        truth.wait_for(lambda w: w.t_s > 50 and not w.people, 120, "both gone")
        retry_until(lambda: state.messages[-1].expression == m.ExpressionAction.EYE_SLEEP,
                    60, 0.2, "asleep")
        assert any(s.last_greeting_ns for s in state.messages), state.messages[-1]
        assert sounds(state.messages)[-1] == "farewell", sounds(state.messages)
        assert watch.one_truth_problems(start) == []


def test_a_fan_is_clutter_the_robot_sleeps_and_still_greets_a_visitor(tmp_path: Path) -> None:
    """A fan the radar sees moving stops counting as a person after the clutter time
    (6 s here): the robot falls asleep beside it, wakes for a visitor's face, says
    goodbye when they leave and sleeps again, the fan still running."""
    with robot_on(tmp_path, str(SCENARIOS / "fan_then_visit.toml"),
                  "[people]\nclutter_after_s = 6\n[controller]\nalone_s = 0.0\n") as probe:
        watch = Watch(probe)
        truth, state = watch.truth, watch.state
        people = Arrivals(probe, keys.PEOPLE_STATE)
        retry_until(lambda: bool(people.messages and watch.states.messages), 60, 0.1,
                    "the latched people/state and controller/state")
        visitor = truth.wait_for(lambda w: bool(w.people), 120, "the visitor")
        came = time.monotonic()
        assert visitor.clutter  # the fan runs all along
        # Before the visitor came, the fan had stopped counting and the robot slept.
        assert people.in_effect(came - 0.5).people == [], people.messages[-3:]
        assert watch.states.in_effect(came - 0.5).expression == m.ExpressionAction.EYE_SLEEP
        truth.wait_for(lambda w: w.t_s > 40 and not w.people, 120, "the visitor gone")
        retry_until(lambda: state.messages[-1].expression == m.ExpressionAction.EYE_SLEEP,
                    60, 0.2, "asleep again beside the fan")
        assert sounds(state.messages) == ["greeting", "farewell"], sounds(state.messages)


def test_someone_walking_past_is_never_greeted(tmp_path: Path) -> None:
    with robot_on(tmp_path, "passer_by") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        first = truth.wait_for(lambda w: any(p.in_radar for p in w.people), 120, "a passer-by")
        truth.wait_for(lambda w: w.lap >= first.lap + 2, 120, "two more walks past")
        assert "greeting" not in sounds(state.messages), state.messages[-5:]


def test_in_the_dark_the_radar_alone_wakes_the_eyes_and_nobody_is_greeted(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, "dark") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        state = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
        faces = Collector[m.FacePosition](probe, keys.FACE, camera="front")
        near = truth.wait_for(lambda w: any(p.distance_m < 1.2 for p in w.people), 120,
                              "the visitor close")
        assert not any(p.in_camera for p in near.people)  # the camera is covered
        retry_until(lambda: state.messages[-1].expression == m.ExpressionAction.EYE_AWAKE,
                    60, 0.2, "awake for a person only the radar sees")
        truth.wait_for(lambda w: w.lap > near.lap and w.t_s > 2, 120, "the next lap")
        assert "greeting" not in sounds(state.messages)
        assert faces.messages == []


def test_a_crowd_of_five_keeps_every_service_up_and_the_people_bounded(
        tmp_path: Path) -> None:
    with robot_on(tmp_path, "crowd") as probe:
        truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
        people = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
        five = truth.wait_for(lambda w: len(w.people) == 5, 120, "five people")
        truth.wait_for(lambda w: w.lap > five.lap, 120, "a whole lap of the crowd")
        assert people.messages and max(len(s.people) for s in people.messages) <= 5
        live = probe.node_instances()
        expected = {e.name for e in available_services() if not e.on_request}
        assert expected <= {key.split("/")[-1] for key in live}, sorted(live)
