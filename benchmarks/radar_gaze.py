"""Benchmark: an angle-radar target -> the eyes turned toward it (first contact, no face).

Starts `buddybot router`, `buddybot run people`, `buddybot run controller`
and `buddybot run eyes` on loopback; a probe publishes `RadarTargets` on
`radar/1/targets` at 10 Hz for one person at a bearing outside the
camera's view, and times from the first report's put to the first
`eyes/direction` within `--tolerance-deg` of that bearing (four router
crossings). `--page` times up to the real eye page in a headless
Chromium, the figure the look-before-see target counts, smoothing included.

    .venv/bin/python benchmarks/radar_gaze.py [--count N] [--tolerance-deg D] [--page]

Method in full: docs/controller.md, 'Method of benchmarks/radar_gaze.py'.
"""

from __future__ import annotations

import argparse
import math
import shutil
import statistics
import sys
import threading
import time
from typing import Any

import results
from common import CHROMIUM_ARGS, host, percentile, services_up, summary

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, free_port, wait_port

CONFIG = """
[people]
absence_hold_s = 0.1
track_coast_s = 0.25
radar_timeout_s = 0.5
[controller]
farewell_delay_s = 0.0
sleepy_s = 0.0
gaze_hold_s = 0.1
recover_s = 0.2
"""
PAGE_CONFIG = """
[eye_renderer]
port = {port}
browser = false
"""
BEARING_DEG = 40.0
DISTANCE_M = 2.0

WATCH = """([goal, tol]) => {
  // Runs after the page's own frame callback in every frame (registered
  // outside a frame, after it), so it reads what that frame drew.
  const e = window.eyes, w = { target: 0, base: 0, drawn: 0 };
  window.gazeWatch = w;
  const near = (v) => Math.abs(v - goal) <= tol;
  const look = () => {
    const t = performance.timeOrigin + performance.now();
    if (!w.target && near(e.target.yaw)) w.target = t;
    if (!w.base && near(e.base.yaw)) w.base = t;
    if (!w.drawn && near(e.cur.yaw)) w.drawn = t;
    if (!(w.target && w.base && w.drawn)) requestAnimationFrame(look);
  };
  requestAnimationFrame(look);
}"""
"""Records, in page time (ms since the epoch), the first frame drawn with the
commanded target near `goal`, with the eased commanded gaze near it and with
the drawn gaze (plus the saccade offset) near it."""


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
        self.at_ns = 0
        """perf_counter_ns() when the newest direction arrived."""
        self._cond = threading.Condition()
        node.subscribe(keys.EYES_DIRECTION, self._on)

    def _on(self, msg: m.EyesDirection, _key: str) -> None:
        with self._cond:
            if msg.yaw != self.yaw:
                self.at_ns = time.perf_counter_ns()
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


class People:
    """Whether the newest `people/state` has anybody in it."""

    def __init__(self, node: Node) -> None:
        self.count: int | None = None
        node.subscribe(keys.PEOPLE_STATE, self._on)

    def _on(self, msg: m.PeopleState, _key: str) -> None:
        self.count = len(msg.people)


def page_offset_ms(page: Any) -> float:
    """The page's epoch clock (performance.timeOrigin + now()) minus ours, from
    the quickest of a few round trips: one clock for the put and the frames,
    even if the wall clock was slewed since the page opened."""
    best = (math.inf, 0.0)
    for _ in range(5):
        before = time.time() * 1000.0
        page_ms = page.evaluate("performance.timeOrigin + performance.now()")
        after = time.time() * 1000.0
        best = min(best, (after - before, page_ms - (before + after) / 2))
    return best[1]


def page_trial(pub: object, eyes: Eyes, page: Any, bearing: float,
               tolerance: float) -> dict[str, float]:
    """Reports at 10 Hz until the page draws the gaze at `bearing`; ms from the
    first put to the bus direction and to each page frame of `WATCH`."""
    page.evaluate(WATCH, [bearing, tolerance])
    start_ms = time.time() * 1000.0 + page_offset_ms(page)
    start = time.perf_counter_ns()
    bus_ms: float | None = None
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        pub.put(report(bearing))  # type: ignore[attr-defined]
        next_put = time.monotonic() + 0.1
        while time.monotonic() < next_put:
            if bus_ms is None and eyes.wait(bearing, tolerance, 0.005):
                bus_ms = (eyes.at_ns - start) / 1e6
            w = page.evaluate("window.gazeWatch")
            if bus_ms is not None and w["target"] and w["base"] and w["drawn"]:
                return {"bus": bus_ms, **{k: w[k] - start_ms for k in w}}
            time.sleep(0.005)  # polling the page's record, which holds the times itself
    raise TimeoutError(f"the page never drew the gaze at {bearing} deg "
                       f"(bus yaw {eyes.yaw}, page {page.evaluate('window.gazeWatch')})")


def page_leave(pub: object, eyes: Eyes, people: People, page: Any) -> None:
    """Empty reports until the people service has dropped the person and the
    page (and the bus) look ahead again."""
    deadline = time.monotonic() + 15.0
    while time.monotonic() < deadline:
        pub.put(report(None))  # type: ignore[attr-defined]
        next_put = time.monotonic() + 0.1
        if (eyes.wait(0.0, 0.5, 0.1) and people.count == 0
                and abs(page.evaluate("window.eyes.base.yaw")) <= 0.5):
            return
        time.sleep(max(0.0, next_put - time.monotonic()))  # reports at 10 Hz, as the sensor
    raise TimeoutError(f"nobody never came back (people {people.count}, bus yaw {eyes.yaw})")


def line(name: str, values: list[float]) -> str:
    return (f"{name:<58} median {statistics.median(values):6.1f} ms  p90 "
            f"{percentile(values, 0.9):6.1f} ms  max {max(values):6.1f} ms  (n={len(values)})")


def run_page(args: argparse.Namespace) -> int:
    """The `--page` part: up to the eyes drawn by the real page."""
    chromium = shutil.which("chromium")
    if chromium is None:
        print("chromium not installed (scripts/chromium.sh installs it)", file=sys.stderr)
        return 1
    from playwright.sync_api import sync_playwright

    port = free_port()
    names = ("people", "controller", "eyes", "eye-renderer")
    config = CONFIG + PAGE_CONFIG.format(port=port)
    trials: list[dict[str, float]] = []
    with (services_up(names, config, "buddybot-bench-radar-gaze-page-") as endpoint,
          Node("bench", connect=[endpoint]) as node, sync_playwright() as pw):
        Collector(node, keys.PEOPLE_STATE).wait_for(timeout=30, what="people up")
        Collector(node, keys.CONTROLLER_STATE).wait_for(timeout=30, what="controller up")
        wait_port(port, 30)
        eyes, people = Eyes(node), People(node)
        pub = node.publisher(keys.RADAR_TARGETS, device="1")
        browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 800, "height": 480})
            page.goto(f"http://127.0.0.1:{port}/eyes?eye=both")
            page.wait_for_function("window.eyes && window.eyes.ready "
                                   "&& window.eyes.cur.calm < 0.002", timeout=30_000)
            print(f"Chromium {browser.version}, headless, software rendering, 800x480, "
                  "both eyes, blinks and saccades on")
            page_trial(pub, eyes, page, BEARING_DEG, args.tolerance_deg)  # warm up
            page_leave(pub, eyes, people, page)
            for i in range(args.count):
                bearing = BEARING_DEG if i % 2 else -BEARING_DEG
                trials.append(page_trial(pub, eyes, page, bearing, args.tolerance_deg))
                page_leave(pub, eyes, people, page)
        finally:
            browser.close()
    tol = args.tolerance_deg
    print(host())
    print(f"radar target at +-{BEARING_DEG:.0f} deg, {DISTANCE_M} m, no face, first contacts; "
          f"from the first report's put to:")
    print(line(f"eyes/direction within {tol} deg (bus)", [t["bus"] for t in trials]))
    print(line("first frame drawn with the new target", [t["target"] for t in trials]))
    print(line(f"page draws the commanded gaze within {tol} deg (target <= 150)",
               [t["base"] for t in trials]))
    print(line("  of which the page's easing", [t["base"] - t["target"] for t in trials]))
    print(line(f"drawn gaze incl. saccade offset within {tol} deg", [t["drawn"] for t in trials]))
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=30)
    parser.add_argument("--tolerance-deg", type=float, default=3.0)
    parser.add_argument("--page", action="store_true",
                        help="up to the real eye page's drawn gaze (eye-renderer, Chromium)")
    args = parser.parse_args()
    if args.page:
        return run_page(args)
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
    raise SystemExit(results.run(__file__, main))
