"""The board's map wiring, without a server: what reaches the pages' `map` slot."""

from __future__ import annotations

import math

from buddybot.contract import messages as m
from buddybot.dashboard import radar_map as rm
from buddybot.dashboard.pages import Board
from buddybot.dashboard.settings import DashboardSettings

from .test_radar_map import person, report


def board(configured: rm.Configured | None = None) -> Board:
    return Board(DashboardSettings(), 8080, [], configured)


def test_an_ld2410_only_robot_gets_no_map() -> None:
    b = board()
    b.deliver([("presence", m.PresenceDetection(
        stamp_ns=1, target_state=m.PresenceTarget.MOVING,
        presence_state=m.PresenceState.IN_RANGE, distance_m=1.0))])
    b.refresh_map()
    assert "map" not in b.state


def test_targets_people_zones_and_the_camera_reach_the_map() -> None:
    b = board(rm.Configured(camera={"fx": 600.0}))
    b.deliver([("targets:4/0", report([(2.0, 0.5)]))])
    scene = b.state["map"]
    assert len(scene["sensors"][0]["targets"]) == 1
    assert scene["fov"] is None  # fx alone, no frame width yet
    b.deliver([
        ("faces", m.FaceDetections(stamp_ns=1, frame_id="cam", width=640, height=480)),
        ("zones", [rm.Zone("ignore", 1.0, 2.0, 0.0, 1.0, "TV")]),
        ("people", m.PeopleState(stamp_ns=1, people=[person(3, 2.0, math.atan2(0.5, 2.0))])),
        ("controller", m.ControllerState(stamp_ns=1, phase="engaged", person_id=3)),
    ])
    scene = b.state["map"]
    assert scene["fov"]["from"] == "[face_detector] of this machine's config: fx 600 px over 640 px"
    assert scene["zones"][0]["name"] == "TV" and scene["zones_from"] == rm.PRESENCE_PARAMS
    assert [p["followed"] for p in scene["people"]] == [True]
    # The controller's state still goes to the pages as before; people/state is the map's.
    assert b.state["controller"]["person_id"] == 3 and "people" not in b.state
    # The live camera parameters win over the config.
    b.deliver([("camera_params", {"hfov_deg": 70.0})])
    assert b.state["map"]["fov"]["hfov_deg"] == 70.0
