"""Benchmark: an angle-radar target -> the eyes turned toward it (first contact, no face).

Starts `buddybot router`, `buddybot run people`, `buddybot run controller`
and `buddybot run eyes` on loopback; a probe publishes `RadarTargets` on
`radar/1/targets` at 10 Hz, as an LD2450 bridge does, for one person standing
at a bearing outside the camera's view (alternately 40 deg left and right),
and times from the first report's put to the first `eyes/direction` whose yaw
is within `--tolerance-deg` of that bearing. The chain: targets -> people
(tracker, a new person) -> `people/state` -> controller (`RadarGaze`, a
`Look`) -> `eyes/control` -> eyes driver -> `eyes/direction`: four router
crossings. The eyes driver passes the direction on at once (the pages'
motion model animates the saccade on screen, after `eyes/direction`), so
there is no smoothing delay on the bus. Between trials the person leaves
(empty reports) and the eyes return to centre (short holds in the config).

    .venv/bin/python benchmarks/radar_gaze.py [--count N] [--tolerance-deg D]
"""

from __future__ import annotations

import argparse
import math
import threading
import time

from common import host, services_up, summary

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector

CONFIG = """
[people]
absence_hold_s = 0.1
track_coast_s = 0.25
radar_timeout_s = 0.5
[controller]
absence_hold_s = 0.0
sleepy_s = 0.0
gaze_hold_s = 0.1
recover_s = 0.2
"""
BEARING_DEG = 40.0
DISTANCE_M = 2.0


def report(bearing_deg: float | None) -> m.RadarTargets:
    targets = []
    if bearing_deg is not None:
        b = math.radians(bearing_deg)
        x, y = DISTANCE_M * math.cos(b), DISTANCE_M * math.sin(b)
        targets.append(m.RadarTarget(
            slot=0, x_m=-y, y_m=x, speed_mps=0.0, resolution_m=0.32,
            position=m.Point(x=x, y=y, z=0.0), bearing_rad=b, distance_m=DISTANCE_M))
    return m.RadarTargets(stamp_ns=m.now_ns(), device_id=1, radar_id=0, targets=targets)


class Eyes:
    """The newest `eyes/direction` yaw, and a wait for a yaw near a value."""

    def __init__(self, node: Node) -> None:
        self.yaw: float | None = None
        self._cond = threading.Condition()
        node.subscribe(keys.EYES_DIRECTION, self._on)

    def _on(self, msg: m.EyesDirection, _key: str) -> None:
        with self._cond:
            self.yaw = msg.yaw
            self._cond.notify_all()

    def near(self, yaw_deg: float, tolerance: float) -> bool:
        return self.yaw is not None and abs(self.yaw - yaw_deg) <= tolerance

    def wait(self, yaw_deg: float, tolerance: float, timeout: float) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: self.near(yaw_deg, tolerance), timeout)


def trial(pub: object, eyes: Eyes, bearing: float, tolerance: float) -> float:
    """Reports at 10 Hz until the eyes point at `bearing`; ms from the first put."""
    start = time.perf_counter_ns()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        pub.put(report(bearing))  # type: ignore[attr-defined]
        if eyes.wait(bearing, tolerance, 0.1):
            return (time.perf_counter_ns() - start) / 1e6
    raise TimeoutError(f"the eyes never turned to {bearing} deg (last yaw {eyes.yaw})")


def leave(pub: object, eyes: Eyes) -> None:
    """Empty reports until the eyes are back at the centre."""
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        pub.put(report(None))  # type: ignore[attr-defined]
        if eyes.wait(0.0, 0.5, 0.1):
            time.sleep(0.3)  # the person's LEFT and the controller's departure settle
            return
    raise TimeoutError("the eyes never came back to centre")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=30)
    parser.add_argument("--tolerance-deg", type=float, default=3.0)
    args = parser.parse_args()
    names = ("people", "controller", "eyes")
    with (services_up(names, CONFIG, "buddybot-bench-radar-gaze-") as endpoint,
          Node("bench", connect=[endpoint]) as node):
        Collector(node, keys.PEOPLE_STATE).wait_for(timeout=30, what="people up")
        Collector(node, keys.CONTROLLER_STATE).wait_for(timeout=30, what="controller up")
        eyes = Eyes(node)
        pub = node.publisher(keys.RADAR_TARGETS, device="1")
        trial(pub, eyes, BEARING_DEG, args.tolerance_deg)  # warm up (and wait for the eyes)
        leave(pub, eyes)
        latencies = []
        for i in range(args.count):
            bearing = BEARING_DEG if i % 2 else -BEARING_DEG
            latencies.append(trial(pub, eyes, bearing, args.tolerance_deg))
            leave(pub, eyes)
    print(host())
    print(summary(f"radar target -> eyes/direction within {args.tolerance_deg} deg "
                  f"(first contact, no face; target <= 150 ms median)", latencies))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
