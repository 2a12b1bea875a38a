"""What the map shows: targets, trails, zones, the camera's view, the followed person."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest

from buddybot.contract import messages as m
from buddybot.dashboard import map_geometry as geo
from buddybot.dashboard import radar_map as rm


def report(points: list[tuple[float, float]], device: int = 4, radar: int = 0) -> m.RadarTargets:
    return m.RadarTargets(stamp_ns=1, device_id=device, radar_id=radar, targets=[
        m.RadarTarget(slot=s, x_m=-y, y_m=x, speed_mps=0.0, resolution_m=0.3,
                      position=m.Point(x=x, y=y, z=0.0), bearing_rad=math.atan2(y, x),
                      distance_m=math.hypot(x, y)) for s, (x, y) in enumerate(points)])


def person(pid: int, distance: float, yaw: float | None) -> m.Person:
    return m.Person(id=pid, distance_m=distance, zone="SOCIAL", seen_by="RADAR",
                    zone_since_ns=1, arrived_ns=1, engagement="ENGAGED",
                    engagement_since_ns=1, yaw_rad=yaw)


def view_of(scene: dict[str, Any]) -> geo.MapView:
    w, h = scene["size"]
    return geo.MapView(w, h, scene["origin"][0], scene["origin"][1], scene["scale"])


def test_no_map_before_an_angle_radar_reports() -> None:
    rmap = rm.RadarMap()
    rmap.people = m.PeopleState(stamp_ns=1, people=[person(1, 2.0, 0.1)])
    assert not rmap and rmap.scene(10.0) is None


def test_targets_are_where_their_camera_frame_position_says() -> None:
    rmap = rm.RadarMap()
    rmap.add(report([(2.0, 1.0), (3.0, -1.5)]), 10.0)
    scene = rmap.scene(10.0)
    assert scene is not None
    view = view_of(scene)
    (s,) = scene["sensors"]
    assert s["key"] == "4/0" and not s["silent"]
    assert [t["at"] for t in s["targets"]] == [
        pytest.approx(list(view.to_canvas(2.0, 1.0)), abs=0.1),
        pytest.approx(list(view.to_canvas(3.0, -1.5)), abs=0.1)]
    assert s["targets"][0]["bearing_deg"] == pytest.approx(26.6)
    assert s["targets"][0]["distance_m"] == pytest.approx(2.24)
    assert s["targets"][0]["at"][0] < scene["origin"][0]  # the robot's left: drawn left


def test_trails_follow_a_slot_and_break_where_it_jumps_or_pauses() -> None:
    rmap = rm.RadarMap()
    for i in range(10):  # slot 0 walks 5 cm per report
        rmap.add(report([(2.0, 1.0 - 0.05 * i)]), 10.0 + 0.1 * i)
    rmap.add(report([(4.0, -2.0)]), 11.0)          # slot 0 now someone else: a new run
    rmap.add(report([(4.0, -1.95)]), 11.1)
    rmap.add(report([(4.0, -1.9)]), 12.0)          # after a pause: alone, no run
    scene = rmap.scene(12.0)
    assert scene is not None
    trails = scene["sensors"][0]["trails"]
    assert [len(t) for t in trails] == [10, 2]
    assert trails[0][0][2] == pytest.approx(10.0) and trails[0][-1][2] == pytest.approx(10.9)


def test_trails_keep_only_the_last_seconds_and_stay_bounded() -> None:
    rmap = rm.RadarMap(trail_s=3.0)
    for i in range(2000):
        rmap.add(report([(2.0, 0.0), (3.0, 0.0), (4.0, 0.0)]), i / 1000)
    scene = rmap.scene(2.0)
    assert scene is not None
    assert sum(len(t) for t in scene["sensors"][0]["trails"]) <= rm.MAX_TRAIL_POINTS
    late = rmap.scene(2.0 + 3.5)
    assert late is not None and late["sensors"][0]["trails"] == []


def test_a_silent_sensor_shows_no_targets_and_is_forgotten_later() -> None:
    rmap = rm.RadarMap()
    rmap.add(report([(2.0, 0.0)]), 10.0)
    rmap.add(report([(1.0, 0.5)], device=5), 10.0)
    rmap.add(report([(1.0, 0.5)], device=5), 10.0 + rm.FORGET_S)
    scene = rmap.scene(10.0 + rm.STALE_S + 0.1)
    assert scene is not None
    assert [(s["key"], s["silent"], len(s["targets"])) for s in scene["sensors"]] == [
        ("4/0", True, 0), ("5/0", False, 1)]
    scene = rmap.scene(10.0 + rm.FORGET_S + 1.0)
    assert scene is not None
    assert [s["key"] for s in scene["sensors"]] == ["5/0"]
    assert scene["sensors"][0]["index"] == 1  # its colour stays


def test_the_followed_person_from_controller_state_and_people_state() -> None:
    rmap = rm.RadarMap()
    rmap.add(report([]), 10.0)
    rmap.people = m.PeopleState(stamp_ns=1, people=[person(2, 3.0, None),
                                                    person(3, 2.0, math.radians(30))])
    scene = rmap.scene(10.0)
    assert scene is not None and not any(p["followed"] for p in scene["people"])
    rmap.controller = m.ControllerState(stamp_ns=1, phase="engaged", person_id=3)
    assert rmap.followed() is not None and rmap.followed().id == 3  # type: ignore[union-attr]
    scene = rmap.scene(10.0)
    assert scene is not None
    other, followed = scene["people"]
    assert followed["followed"] and followed["yaw_deg"] == pytest.approx(30.0)
    view = view_of(scene)
    assert followed["at"] == pytest.approx(list(view.to_canvas(2.0 * math.cos(math.radians(30)),
                                                               2.0 * math.sin(math.radians(30)))),
                                           abs=0.1)
    # No bearing: a ring at the distance, no point.
    assert other["at"] is None and other["ring_px"] == pytest.approx(3.0 * view.scale, abs=0.1)
    rmap.controller = m.ControllerState(stamp_ns=1, phase="engaged", person_id=9)
    assert rmap.followed() is None


def test_zones_fov_and_their_sources_in_the_scene() -> None:
    rmap = rm.RadarMap()
    rmap.add(report([(1.0, 0.0)]), 10.0)
    zones = rm.parse_zones([{"mode": "ignore", "name": "TV", "x": [2.6, 3.6], "y": [1.6, 2.6]}])
    assert zones is not None
    rmap.set_zones(zones, rm.PRESENCE_PARAMS)
    rmap.set_fov((math.radians(28), math.radians(-28)), "here")
    scene = rmap.scene(10.0)
    assert scene is not None
    view = view_of(scene)
    (zone,) = scene["zones"]
    assert zone["mode"] == "ignore" and zone["name"] == "TV"
    assert zone["poly"] == [pytest.approx(list(p), abs=0.1)
                            for p in geo.rectangle(view, 2.6, 3.6, 1.6, 2.6)]
    # The zone counts for the extent: its far corner is on the canvas.
    assert view.contains(*view.to_canvas(3.6, 2.6))
    assert scene["fov"]["hfov_deg"] == pytest.approx(56.0) and scene["fov"]["from"] == "here"


@pytest.mark.parametrize(("value", "expected"), [
    (None, None),
    ("garbage", None),
    ([], []),
    ([{"name": "room", "mode": "detect", "x": [0.5, 4.0], "y": [2.0, -2.0]}],
     [rm.Zone("detect", 0.5, 4.0, -2.0, 2.0, "room")]),
    ([{"name": "door", "mode": "ignore", "x": [1, 2], "y": [0, 1]},
      {"name": "off", "mode": "off", "x": [1, 2], "y": [0, 1]},
      {"name": "IGNORE", "mode": "IGNORE", "x": [1, 2], "y": [0, 1]},
      {"name": "half", "mode": "ignore", "x": [1, 2]},
      {"name": "three", "mode": "ignore", "x": [1, 2, 3], "y": [0, 1]},
      {"name": "bool", "mode": "ignore", "x": [True, 2], "y": [0, 1]},
      {"name": "nan", "mode": "ignore", "x": [float("nan"), 2], "y": [0, 1]},
      {"name": "text", "mode": "ignore", "x": "1..2", "y": [0, 1]},
      "not a table", 7],
     [rm.Zone("ignore", 1.0, 2.0, 0.0, 1.0, "door")]),
])
def test_zones_are_read_leniently_one_bad_zone_never_hides_the_others(
        value: Any, expected: list[rm.Zone] | None) -> None:
    assert rm.parse_zones(value) == expected


def test_many_zones_are_bounded() -> None:
    zone = {"name": "z", "mode": "ignore", "x": [1, 2], "y": [0, 1]}
    zones = rm.parse_zones([zone] * 1000)
    assert zones is not None and len(zones) == rm.MAX_ZONES


def test_live_parameters_win_over_this_machines_config() -> None:
    door = rm.Zone("ignore", 1.0, 2.0, 0.0, 1.0)
    assert rm.choose_zones([], [door]) == ([], rm.PRESENCE_PARAMS)
    assert rm.choose_zones(None, [door])[0] == [door]
    assert rm.choose_zones(None, None) == ([], "")
    fov, where = rm.choose_fov({"fx": 600.0}, {"hfov_deg": 90.0}, 640)
    assert fov is not None and math.degrees(fov[0] - fov[1]) == pytest.approx(56.14, abs=0.01)
    assert where == "params/face-detector: fx 600 px over 640 px"
    fov, where = rm.choose_fov(None, {"fx": 600.0, "hfov_deg": 90.0}, None)
    assert fov is not None and math.degrees(fov[0]) == pytest.approx(45.0)
    assert where == "[face_detector] of this machine's config: hfov_deg 90"
    fov, where = rm.choose_fov({"fx": 600.0}, {}, None)
    assert fov is None and where.startswith("unknown")


def test_params_replies_and_the_config_tables_are_read_by_name() -> None:
    reply = m.ParamReply(node="face-detector", table="face_detector", params=[
        m.ParamInfo(name="fx", value=600, type="", range="", live=False),
        m.ParamInfo(name="cx", value=None, type="", range="", live=False),
        m.ParamInfo(name="hfov_deg", value="wide", type="", range="", live=False)])
    assert rm.number_params(reply, rm.CAMERA_FIELDS) == {"fx": 600.0}
    assert rm.number_params(None, rm.CAMERA_FIELDS) == {}
    refused = m.ParamReply(node="x", table="x", error="unknown")
    assert rm.params_value(refused, "fx") is None
    config = SimpleNamespace(
        radar_presence=SimpleNamespace(zones=[{"name": "room", "mode": "detect", "x": [0, 3],
                                               "y": [-1, 1]}]),
        face_detector=SimpleNamespace(fx=600.0, cx=None, hfov_deg=None),
        camera=SimpleNamespace(width=1280))
    got = rm.Configured.read(config)
    assert got.zones == [rm.Zone("detect", 0.0, 3.0, -1.0, 1.0, "room")]
    assert dict(got.camera) == {"fx": 600.0} and got.width == 1280
    # Today's config has no zones field and the camera no width: not known, no error.
    bare = rm.Configured.read(SimpleNamespace(radar_presence=SimpleNamespace(),
                                              camera=SimpleNamespace(width=None)))
    assert bare == rm.Configured()


def world(t_s: float, *people: tuple[int, float, float, float]) -> m.SimWorld:
    """A simulated world's truth: (id, x, y, facing) per person, a fan at (1.5, 0.8)."""
    return m.SimWorld(stamp_ns=1, scenario="visit", t_s=t_s, lap=0, people=[
        m.SimPerson(id=i, face="collins", position=m.Point(x=x, y=y, z=0.2), vx_mps=0.0,
                    vy_mps=0.0, facing_rad=f, distance_m=math.hypot(x, y),
                    bearing_rad=math.atan2(y, x), in_radar=True, in_camera=i == 1,
                    name="Eileen" if i == 1 else None) for i, x, y, f in people],
        clutter=[m.SimClutter(kind="fan", position=m.Point(x=1.5, y=0.8, z=0.0))])


def test_the_simulated_truth_is_drawn_where_people_really_are_and_fades_when_silent() -> None:
    rmap = rm.RadarMap()
    rmap.set_truth(world(12.0, (1, 1.0, 0.1, math.pi), (2, 3.0, -1.0, 0.0)), 10.0)
    assert rmap  # a map with no angle radar: the truth alone
    scene = rmap.scene(10.2)
    assert scene is not None and scene["sensors"] == []
    view = view_of(scene)
    truth = scene["truth"]
    assert truth["scenario"] == "visit" and truth["t_s"] == 12.0
    first, second = truth["people"]
    assert first["at"] == pytest.approx(list(view.to_canvas(1.0, 0.1)), abs=0.1)
    assert (first["name"], first["in_camera"], second["in_camera"]) == ("Eileen", True, False)
    assert first["facing"][1] > first["at"][1]  # facing the robot: the arrow points down
    assert truth["clutter"][0]["at"] == pytest.approx(list(view.to_canvas(1.5, 0.8)), abs=0.1)
    later = rmap.scene(10.0 + rm.STALE_S + 0.5)
    assert later is not None and later["truth"] is None
