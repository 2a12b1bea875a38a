"""The attention rule, motion and their use by the behaviour, on a fake clock: a glance
at a newcomer, the gaze shared between engaged people, gaze aversion, a passer-by
not greeted, a visitor walking away said goodbye to as they go, the alert face for
someone noticed with nowhere to look and for someone rushing in."""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

import msgspec
import pytest

from buddybot.contract.messages import ExpressionAction as X
from buddybot.controller.attention import NEWCOMER_S, Attention
from buddybot.controller.behaviour import Behaviour, Command, Look, PlaySound, SetExpression
from buddybot.controller.kinematics import MIN_SPAN_S, Kinematics
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze
from buddybot.sdk.persons import Person

S = msgspec.convert({"recover_s": 0.0}, ControllerSettings)


def person(pid: int, yaw_deg: float | None = 0.0, distance: float = 1.2,
           seen_by: str = "BOTH", engagement: str = "ENGAGED", zone: str = "PERSONAL"
           ) -> Person:
    return Person(id=pid, zone=zone, engagement=engagement, distance_m=distance,
                  seen_by=seen_by, yaw_rad=None if yaw_deg is None else math.radians(yaw_deg))


def run(att: Attention, people: Sequence[Person], main: int | None, start: float,
        seconds: float, s: ControllerSettings = S) -> list[tuple[float, int | None, str]]:
    """The focus every 50 ms for `seconds` from `start`."""
    out = []
    for i in range(round(seconds / 0.05)):
        t = start + i * 0.05
        f = att.update(s, t, people, main)
        out.append((t, f.person_id, f.reason))
    return out


# -- attention (pure) --

def test_a_newcomer_is_glanced_at_within_a_second_then_the_main_person_again() -> None:
    att = Attention(random.Random(1))
    alone = run(att, [person(1)], 1, 0.0, 3.0)
    assert {pid for _t, pid, _r in alone} == {1}
    both = [person(1), person(2, 30.0, 4.0, "RADAR", "NONE", "PUBLIC")]
    seen = run(att, both, 1, 3.0, 3.0)
    glance = [t for t, pid, _r in seen if pid == 2]
    assert glance and glance[0] - 3.0 < NEWCOMER_S
    assert {r for _t, pid, r in seen if pid == 2} == {"newcomer"}
    assert glance[-1] - glance[0] == pytest.approx(S.glance_s, abs=0.06)
    assert seen[-1][1] == 1  # back to the main person
    # Someone far who is not engaging is not glanced at again.
    assert [pid for _t, pid, _r in run(att, both, 1, 6.0, 10.0)] == [1] * 200


def test_a_person_without_a_direction_is_not_glanced_at() -> None:
    att = Attention(random.Random(1))
    run(att, [person(1)], 1, 0.0, 1.0)
    seen = run(att, [person(1), person(2, None, 2.0, "RADAR")], 1, 1.0, 2.0)
    assert {pid for _t, pid, _r in seen} == {1}


@pytest.mark.parametrize("engagement, zone", [("ENGAGING", "PUBLIC"), ("NONE", "SOCIAL")])
def test_the_gaze_is_shared_between_engaged_people_and_comes_back(engagement: str,
                                                                  zone: str) -> None:
    att = Attention(random.Random(7))
    both = [person(1), person(2, -20.0, 1.4, "RADAR", engagement, zone)]
    run(att, [person(1)], 1, 0.0, 1.0)
    seen = run(att, both, 1, 1.0, 30.0)
    shares = [t for t, pid, reason in seen if reason == "share" and pid == 2]
    assert shares, "never looked at the second engaged person"
    # Several separate glances, each followed by the main person again.
    starts = [t for (t, _p, r), (_t0, _p0, r0) in zip(seen[1:], seen, strict=False)
              if r == "share" and r0 != "share"]
    assert len(starts) >= 4, starts
    main = sum(1 for _t, pid, _r in seen if pid == 1)
    assert main > 0.6 * len(seen)


def test_eye_contact_breaks_now_and_then_but_stays_on_the_face_on_average() -> None:
    att = Attention(random.Random(3))
    offsets = []
    for i in range(400):  # 20 s
        f = att.update(S, i * 0.05, [person(1)], 1)
        offsets.append(f.offset)
    changes = [i for i in range(1, 400) if offsets[i] != offsets[i - 1]]
    gaps = [(b - a) * 0.05 for a, b in zip([0, *changes], [*changes, 399], strict=True)]
    assert changes and max(gaps) < 5.0, gaps
    mean_yaw = abs(sum(o[0] for o in offsets) / len(offsets))
    assert math.degrees(mean_yaw) < 3.0
    assert max(abs(o[0]) for o in offsets) == pytest.approx(math.radians(S.aversion_deg))


def test_no_aversion_without_a_face_or_when_switched_off() -> None:
    att = Attention(random.Random(3))
    radar_only = [person(1, 10.0, 2.0, "RADAR")]
    assert {att.update(S, i * 0.05, radar_only, 1).offset for i in range(200)} == {(0.0, 0.0)}
    off = msgspec.structs.replace(S, aversion_deg=0.0)
    assert {att.update(off, i * 0.05, [person(1)], 1).offset for i in range(200)} == {
        (0.0, 0.0)}


# -- motion (pure) --

def test_motion_from_positions_and_from_distance_alone() -> None:
    k = Kinematics()
    assert k.update(0.0, [person(1, 90.0, 1.5)]) == {}  # one sample: unknown
    # Walking across at 1.5 m: planar speed, no radial speed.
    for i in range(1, 11):
        t = i * 0.1
        y = 1.5 - 1.2 * t
        moving = k.update(t, [Person(id=1, zone="SOCIAL", engagement="NONE",
                                     distance_m=math.hypot(1.5, y), seen_by="RADAR",
                                     bearing_rad=math.atan2(y, 1.5))])
    assert moving[1].speed_mps == pytest.approx(1.2, rel=0.05)
    assert abs(moving[1].radial_mps) < 0.5
    # A distance alone (LD2410): the radial speed is the speed.
    k2 = Kinematics()
    for i in range(8):
        moving = k2.update(i * 0.1, [person(1, None, 1.0 + 0.1 * i, "RADAR")])
    assert moving[1].radial_mps == pytest.approx(1.0) and moving[1].speed_mps == \
        pytest.approx(1.0)
    assert moving[1].nearest_m == pytest.approx(1.0)
    assert MIN_SPAN_S < 0.7


# -- the behaviour --

class Crowded:
    """A behaviour fed `people` states every 50 ms (and the presence they imply)."""

    def __init__(self, **overrides: object) -> None:
        self.s = msgspec.convert({"recover_s": 0.0, **overrides}, ControllerSettings)
        self.t = 0.0
        self.b = Behaviour(self.s, self.t, random.Random(5))
        self.log: list[tuple[float, Command]] = []

    def step(self, people: Sequence[Person], face: Gaze | None = None) -> None:
        """One `people/state` as the service hands it over: the crowd, then presence."""
        self.t += 0.05
        main = people[0].id if people else None
        shown = any(p.seen_by != "NONE" for p in people)
        gazes = {p.id: Gaze(p.yaw_rad or 0.0, 0.0, 100 * (p.distance_m or 1.0))
                 for p in people if p.yaw_rad is not None}
        cmds = self.b.people(self.t, people, gazes, round(self.t * 1e9))
        cmds += self.b.presence(self.t, shown, main, face=bool(
            people and people[0].seen_by in ("CAMERA", "BOTH")))
        if face is not None:
            cmds += self.b.face(self.t, face, 2)
        self.log += [(self.t, c) for c in cmds]

    def sounds(self) -> list[str]:
        return [c.sound for _t, c in self.log if isinstance(c, PlaySound)]

    def expressions(self) -> list[tuple[float, X]]:
        return [(t, c.action) for t, c in self.log if isinstance(c, SetExpression)]


def test_someone_walking_past_with_their_face_in_view_is_not_greeted() -> None:
    rig = Crowded()
    for i in range(100):  # 5 s across at 1.2 m/s, facing the robot all along
        y = 3.0 - 1.2 * i * 0.05
        rig.step([person(1, math.degrees(math.atan2(y, 1.5)), math.hypot(1.5, y))])
    assert rig.sounds() == []
    assert rig.b.state(rig.t).waiting == "dwell"
    for _ in range(40):  # they stop: a visitor after all
        rig.step([person(1, 0.0, 1.5)])
    assert rig.sounds() == ["greeting"]


def test_a_greeted_visitor_walking_away_gets_the_farewell_as_they_go() -> None:
    rig = Crowded()
    for _ in range(60):
        rig.step([person(1, 0.0, 1.0)])
    assert rig.sounds() == ["greeting"]
    rig.b.sound_reply(rig.t, 1, True, "g1")
    rig.b.sound_status(rig.t, "g1", "SUCCEEDED")
    turned = rig.t
    d = 1.0
    for _ in range(20):  # walking away at 1 m/s, back to the camera
        d += 0.05
        rig.step([person(1, None, d, "RADAR", "DISENGAGING")])
    said = [t for t, c in rig.log if isinstance(c, PlaySound) and c.sound == "farewell"]
    assert said and said[0] - turned < 1.0, said
    assert rig.b.counters["farewells_early"] == 1
    # Gone later: no second goodbye.
    for _ in range(20):
        rig.step([])
    assert rig.sounds() == ["greeting", "farewell"]


def test_no_early_farewell_while_someone_else_stays() -> None:
    rig = Crowded()
    for _ in range(60):
        rig.step([person(1, 0.0, 1.0), person(2, -20.0, 1.3, "RADAR")])
    assert rig.sounds() == ["greeting"]
    rig.b.sound_reply(rig.t, 1, True, "g1")
    rig.b.sound_status(rig.t, "g1", "SUCCEEDED")
    d = 1.0
    for _ in range(20):
        d += 0.05
        rig.step([person(1, None, d, "RADAR"), person(2, -20.0, 1.3, "RADAR")])
    assert rig.sounds() == ["greeting"]


def test_a_newcomer_gets_a_look_then_the_face_has_the_gaze_again() -> None:
    rig = Crowded()
    face = Gaze(0.0, 0.0, 120.0)
    for _ in range(40):
        rig.step([person(1, 0.0, 1.2)], face)
    came = rig.t
    newcomer = person(2, 35.0, 4.0, "RADAR", "NONE", "PUBLIC")
    for _ in range(60):
        rig.step([person(1, 0.0, 1.2), newcomer], face)
    looks = [(t, c.gaze) for t, c in rig.log if isinstance(c, Look) and t > came]
    at_newcomer = [t for t, g in looks if g is not None and g.yaw == pytest.approx(
        math.radians(35.0))]
    assert at_newcomer and at_newcomer[0] - came < 1.0
    assert looks[-1][1] is not None and abs(looks[-1][1].yaw) < math.radians(10)


def test_someone_noticed_with_nowhere_to_look_gets_an_alert_face() -> None:
    """An LD2410 alone gives a distance, no direction: the face reacts instead."""
    rig = Crowded()
    rig.step([])
    rig.step([person(1, None, 4.0, "RADAR", "NONE", "PUBLIC")])
    came = rig.t
    for _ in range(60):
        rig.step([person(1, None, 4.0, "RADAR", "NONE", "PUBLIC")])
    shown = rig.expressions()
    assert (came, X.EYE_ALERT) in shown
    back = [t for t, x in shown if t > came and x is not X.EYE_ALERT]
    assert back and back[0] - came == pytest.approx(rig.s.alert_s, abs=0.06)


def test_with_a_direction_the_face_stays_calm() -> None:
    rig = Crowded()
    rig.step([])
    for _ in range(40):
        rig.step([person(1, 40.0, 4.0, "RADAR", "NONE", "PUBLIC")])
    # (the eyes turn to the bearing: test_look_before_see.py)
    assert [x for _t, x in rig.expressions()] == [X.EYE_SLEEP, X.EYE_AWAKE]


@pytest.mark.parametrize("speed, alert", [(1.5, True), (0.5, False)])
def test_rushing_in_alerts_drifting_near_does_not(speed: float, alert: bool) -> None:
    rig = Crowded()
    d = 4.0
    for _ in range(60):  # 3 s: the arrival's own alert (if any) is long over
        rig.step([person(1, 0.0, d, "RADAR", "NONE", "PUBLIC")])
    before = len(rig.expressions())
    while d > 1.0:
        d -= speed * 0.05
        rig.step([person(1, 0.0, d, "RADAR", "NONE", "SOCIAL")])
    later = [x for _t, x in rig.expressions()[before:]]
    assert (X.EYE_ALERT in later) is alert, later


def test_a_change_of_sensor_is_no_leap() -> None:
    """The face's distance and the radar's differ: when the sensors showing a person
    change, their motion starts again instead of reading the difference as a run."""
    k = Kinematics()
    for i in range(6):
        k.update(i * 0.1, [person(1, None, 2.0, "CAMERA")])
    moving = k.update(0.6, [person(1, None, 1.4, "BOTH")])  # the radar's shorter reading
    assert 1 not in moving  # the new sensor's samples are too few to say
    for i in range(7, 12):
        moving = k.update(i * 0.1, [person(1, None, 1.4, "BOTH")])
    assert moving[1].radial_mps == pytest.approx(0.0) and moving[1].closer_m == 0.0
