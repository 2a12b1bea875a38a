"""The `up` status line: formatted from a RobotStatus without a robot, and kept
up to date from the robot's traffic."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.supervisor.status import RobotStatus, StatusMonitor, format_status, rate_hz
from buddybot.tools.testing import retry_until


def test_rate_counts_only_the_window() -> None:
    arrivals = deque([0.0, 7.1, 7.5, 8.0, 9.0, 9.9])
    assert rate_hz(arrivals, now=10.0, window_s=3.0) == 5 / 3.0


def test_status_line_reports_what_an_operator_needs() -> None:
    status = RobotStatus(expected=["camera", "controller", "eyes"], up=["camera", "eyes"])
    status.radar_arrivals.extend([9.1, 9.2, 9.3])
    status.presence = m.PresenceDetection(
        stamp_ns=1, target_state=m.PresenceTarget.MOVING,
        presence_state=m.PresenceState.IN_RANGE, distance_m=1.234)
    status.face_distance_m, status.face_seen_at = 0.8, 9.5
    status.expression = m.ExpressionAction.EYE_AWAKE
    status.camera_fps = 29.96
    status.restarts = 2
    line = format_status(status, now=10.0)
    assert line == ("nodes 2/3 (down: controller) | radar 1.0 Hz | camera 30.0 fps | "
                    "presence IN_RANGE 1.23 m | face 0.80 m | eyes EYE_AWAKE | restarts 2")


def test_stale_face_and_unknown_state() -> None:
    status = RobotStatus(expected=["a"], up=["a"])
    status.face_distance_m, status.face_seen_at = 0.8, 1.0
    line = format_status(status, now=10.0)
    assert line == "nodes 1/1 | radar 0.0 Hz | presence ? | face - | eyes ?"


def test_a_duplicate_node_is_shown() -> None:
    """Two processes with one name (an orphaned robot on the same bus) are not `9/9`."""
    status = RobotStatus(expected=["camera", "eyes"], up=["camera", "eyes"],
                         duplicates=["camera"])
    line = format_status(status, now=10.0)
    assert line.startswith("nodes 2/2 (DUPLICATE: camera) | ")


@pytest.mark.integration
def test_the_radar_rate_counts_reports_of_either_model(
        node_factory: Callable[..., Node]) -> None:
    """An LD2450-only robot shows its radar alive: `radar/*/targets` reports count
    as LD2410 frame arrays do."""
    monitor = StatusMonitor(node_factory("status", probe=True), expected=[])
    sender = node_factory("sender")
    try:
        targets = sender.publisher(keys.RADAR_TARGETS, device="0")
        frames = sender.publisher(keys.RADAR_FRAMES, device="1")

        def sent(count: int) -> bool:
            targets.put(m.RadarTargets(stamp_ns=m.now_ns(), device_id=0, radar_id=0))
            return len(monitor.status.radar_arrivals) >= count

        retry_until(lambda: sent(3), 30, 0.05, "three LD2450 reports counted")
        before = len(monitor.status.radar_arrivals)

        def sent_frames() -> bool:
            frames.put(m.LD2410TargetDataFrameArray(stamp_ns=m.now_ns(), device_id=1,
                                                    sensors=[]))
            return len(monitor.status.radar_arrivals) > before

        retry_until(sent_frames, 30, 0.05, "an LD2410 frame array counted too")
    finally:
        monitor.close()
