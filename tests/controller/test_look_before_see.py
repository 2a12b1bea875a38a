"""Look before see: the eyes follow an angle radar's bearing of the followed person
until the camera sees their face, then the face, without a jump.

The pure part (`Behaviour.radar`) with a fake clock, the mapping of
`people/state` to the `RadarGaze` event, and the whole `Controller` on a fake
node: a person walking past from one side to the other, tracked by the radar
from first contact, their face visible only in the camera's field of view.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.contract.messages import ExpressionAction as X
from buddybot.controller.behaviour import Look, SetExpression
from buddybot.controller.events import (
    Crowd,
    PeopleChanged,
    RadarGaze,
    people_changed,
    radar_point,
)
from buddybot.controller.service import Controller
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze
from buddybot.sdk.persons import PeopleNow

from .fakes import Clock, FakeBot, attached, people_now
from .test_behaviour import Rig

FUSION_DEG = 10.0
"""The people service's default fusion angle: a face is on a radar person only this near."""
CAMERA_HALF_FOV_DEG = 30.0


def radar_gaze(yaw_deg: float, distance_cm: float = 200.0) -> Gaze:
    return Gaze(math.radians(yaw_deg), 0.0, distance_cm)


def looks(commands: list[Any]) -> list[Look]:
    return [c for c in commands if isinstance(c, Look)]


# --- the behaviour --------------------------------------------------------------------------


def test_a_radar_direction_without_a_face_is_looked_at_at_once() -> None:
    rig = Rig(look_around_after_s=0.5)
    rig.presence(True, 1)
    out = rig._rec(rig.b.radar(rig.t, radar_gaze(40.0), 77))
    assert looks(out) == [Look(radar_gaze(40.0), 77)]
    rig.at(3.0)  # tracked: no looking around, no return to centre
    assert not [c for _, c in rig.log if c == Look(None)]
    assert SetExpression(X.EYE_LOOK_RANDOM) not in [c for _, c in rig.log]


def test_the_same_direction_again_is_not_sent_again() -> None:
    rig = Rig()
    rig.presence(True, 1)
    rig._rec(rig.b.radar(rig.t, radar_gaze(10.0)))
    assert looks(rig._rec(rig.b.radar(rig.t, radar_gaze(10.0)))) == []


def test_a_visible_face_keeps_the_gaze_then_the_radar_comes_back() -> None:
    rig = Rig(gaze_hold_s=1.0)
    rig.presence(True, 1)
    rig.face()
    assert looks(rig._rec(rig.b.radar(rig.t, radar_gaze(5.0)))) == []
    rig.at(0.55)  # the face is lost: the radar's direction at once, not the centre
    assert [c for _, c in rig.log if isinstance(c, Look)][-1] == Look(radar_gaze(5.0))


def test_the_eyes_centre_after_the_track_ends() -> None:
    rig = Rig(gaze_hold_s=1.0)
    rig.presence(True, 1)
    rig._rec(rig.b.radar(rig.t, radar_gaze(30.0)))
    rig._rec(rig.b.radar(rig.t, None))
    assert looks(rig.at(0.9)) == []
    assert looks(rig.at(0.2)) == [Look(None)]


def walk_past(rig: Rig, speed_deg_s: float = 30.0) -> list[tuple[float, float, str]]:
    """A person walking from 70 deg right to 70 deg left: radar reports at 10/s from
    first contact; their face at 30/s while within the camera's field of view, its
    direction up to `FUSION_DEG` off the radar's (a badly placed radar). Returns
    (time, yaw in degrees, source) of every Look."""
    rig.presence(True, 1)
    start = rig.t
    out: list[tuple[float, float, str]] = []
    bearing = -70.0
    steps = round(140.0 / speed_deg_s * 30)
    for i in range(steps + 1):
        rig.t = start + i / 30
        bearing = -70.0 + speed_deg_s * i / 30
        cmds: list[Any] = []
        if i % 3 == 0:
            cmds += rig._rec(rig.b.radar(rig.t, radar_gaze(bearing)))
            out += [(rig.t, math.degrees(c.gaze.yaw), "radar") for c in looks(cmds)
                    if c.gaze is not None]
            cmds = []
        if abs(bearing) <= CAMERA_HALF_FOV_DEG:
            face = Gaze(math.radians(bearing + FUSION_DEG * 0.9), 0.0, 200.0)
            cmds += rig.face(face, None)
            out += [(rig.t, math.degrees(c.gaze.yaw), "face") for c in looks(cmds)
                    if c.gaze is not None]
        out += [(rig.t, math.degrees(c.gaze.yaw), "tick")
                for c in looks(rig.people_face() + rig._rec(rig.b.tick(rig.t)))
                if c.gaze is not None]
    return out


@pytest.mark.parametrize("speed_deg_s", [15.0, 30.0, 60.0])
def test_a_person_walking_past_is_followed_from_first_contact_without_a_jump(
        speed_deg_s: float) -> None:
    rig = Rig(gaze_hold_s=1.0)
    seq = walk_past(rig, speed_deg_s)
    assert seq[0][1] == pytest.approx(-70.0) and seq[0][2] == "radar"  # first contact
    assert {"radar", "face"} <= {src for _, _, src in seq}
    steps = [abs(b[1] - a[1]) for a, b in itertools.pairwise(seq)]
    # The largest step is the radar and the face disagreeing (< the fusion angle)
    # plus the walk during one radar report and the face timeout.
    limit = FUSION_DEG + speed_deg_s * 0.6
    assert max(steps) <= limit, (max(steps), seq)
    assert seq[-1][1] > 60.0  # followed to the other side


# --- people/state -> events -------------------------------------------------------------------


def person(pid: int, seen_by: m.SeenBy, distance_m: float = 2.0,
           bearing_deg: float | None = None, pitch_rad: float | None = None) -> m.Person:
    bearing = None if bearing_deg is None else math.radians(bearing_deg)
    return m.Person(id=pid, distance_m=distance_m, zone="SOCIAL", seen_by=seen_by,
                    zone_since_ns=1, arrived_ns=1, engagement="NONE", engagement_since_ns=1,
                    yaw_rad=bearing, pitch_rad=pitch_rad, bearing_rad=bearing)


def people(*persons: m.Person, stamp_ns: int = 5) -> PeopleNow:
    """A `people/state` as the SDK hands it over."""
    return people_now(m.PeopleState(stamp_ns=stamp_ns, people=list(persons)))


def test_the_radar_point_is_the_bearing_at_the_distance() -> None:
    msg = people(person(1, "RADAR", 2.0, 30.0))
    x, y, z = radar_point(msg.people, 1) or (0, 0, 1)
    assert (x, y, z) == pytest.approx((2.0 * math.cos(math.pi / 6), 1.0, 0.0))
    assert radar_point(msg.people, 2) is None
    assert radar_point(people(person(1, "RADAR")).people, 1) is None  # LD2410: no bearing


def test_the_followed_person_stays_the_one_while_the_radar_sees_them() -> None:
    msg = people(person(1, "RADAR", 2.0, 30.0), person(2, "RADAR", 1.0, -30.0))
    assert people_changed(msg.people) == PeopleChanged(True, 2)  # nearest
    assert people_changed(msg.people, follow=1) == PeopleChanged(True, 1)
    assert people_changed(people(person(2, "RADAR")).people, follow=1) == PeopleChanged(True, 2)


def controller() -> tuple[Controller, FakeBot, Clock]:
    settings = msgspec.convert({"recover_s": 0.0}, ControllerSettings)
    clock = Clock()
    return (*attached(settings, clock), clock)


def test_a_new_radar_direction_reaches_the_inbox_and_the_eyes() -> None:
    ctl, node, _clock = controller()
    ctl._on_people(people(person(1, "RADAR", 2.0, 40.0), stamp_ns=10))
    ctl._on_people(people(person(1, "RADAR", 2.0, 40.0), stamp_ns=11))  # same: no news
    ctl._on_people(people(person(1, "RADAR", 2.0, 35.0), stamp_ns=12))
    events = list(ctl._inbox)
    assert [type(e) for e in events if not isinstance(e, Crowd)] == [
        PeopleChanged, RadarGaze, RadarGaze]
    ctl.decision_step(events, next_tick=0.0)
    ctl._inbox.clear()
    sent = node.publishers["controller/eye_control"].sent
    assert [(round(math.degrees(c.yaw), 6), c.stamp_ns) for c in sent] == [(40.0, 10),
                                                                          (35.0, 12)]
    assert sent[0].target_distance_cm == pytest.approx(200.0)


def test_without_angle_radars_nothing_is_posted_but_presence() -> None:
    ctl, _node, _clock = controller()
    ctl._on_people(people(person(1, "RADAR")))
    assert [e for e in ctl._inbox if not isinstance(e, Crowd)] == [PeopleChanged(True, 1)]
