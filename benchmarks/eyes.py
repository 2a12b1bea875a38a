"""Eyes benchmark: animation frame time and published direction -> pupil moving on the page.

Starts a router, `buddybot run eyes` and `buddybot run eye-renderer
--no-browser` as processes (as in production) and opens the page in
Debian's headless Chromium through Playwright. Prints:

* frame time: requestAnimationFrame intervals over a few seconds with the
  page blinking and saccading by itself (target: 60 fps, p95 < 17 ms),
  plus the page's own per-frame update+draw cost (the headroom);
* latency from a published `eyes/direction` (stamp_ns = publish time) to
  the page receiving it and to the first frame drawn with the new target
  (the pupil starts moving in that frame) (target < 30 ms);
* the same from `eyes/control` through the eyes driver.

Same host, same clock: the page uses performance.timeOrigin + now().

    .venv/bin/python benchmarks/eyes.py [--seconds 5] [--count 200]
"""

from __future__ import annotations

import argparse
import math
import shutil
import statistics
import sys
import time
from typing import Any

from common import percentile

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.node import Node
from buddybot.core.testing import Router, free_port, retry_until, run_service, wait_port

CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]


def figures(name: str, values: list[float]) -> None:
    print(f"{name:<44} median {statistics.median(values):7.2f} ms   "
          f"p95 {percentile(values, 0.95):7.2f} ms   p99 {percentile(values, 0.99):7.2f} ms   "
          f"max {max(values):7.2f} ms   (n={len(values)})")


def measure_latency(page: Any, count: int, rate_hz: float, send: Any) -> tuple[list[float],
                                                                              list[float]]:
    """Publish `count` gaze targets; return (to page, to first frame) latencies in ms."""
    page.evaluate("window.eyes.latency.length = 0")
    stamps = []
    for i in range(count):
        stamp = m.now_ns()
        send(stamp, 20.0 if i % 2 else -20.0)
        stamps.append(stamp)
        time.sleep(1.0 / rate_hz)   # pacing the load generator, not synchronisation
    retry_until(lambda: page.evaluate("window.eyes.latency.length") >= count * 0.95, 20,
                what="latency records")
    # JavaScript numbers hold stamp_ns to ~256 ns (doubles): match within 1 us.
    sent = {stamp // 1000 for stamp in stamps}
    to_page, to_frame = [], []
    for rec in page.evaluate("window.eyes.latency"):
        stamp = float(rec["stamp_ns"])
        if rec["frame_ms"] and {int(stamp) // 1000, int(stamp) // 1000 + 1,
                                int(stamp) // 1000 - 1} & sent:
            to_page.append(rec["recv_ms"] - stamp / 1e6)
            to_frame.append(rec["frame_ms"] - stamp / 1e6)
    return to_page, to_frame


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="frame-time window")
    parser.add_argument("--count", type=int, default=200, help="gaze targets to publish")
    parser.add_argument("--rate", type=float, default=20.0, help="gaze targets per second")
    parser.add_argument("--size", default="800x480", help="page size (a small HDMI eye screen)")
    args = parser.parse_args()
    chromium = shutil.which("chromium")
    if chromium is None:
        print("chromium not installed (scripts/chromium.sh installs it)", file=sys.stderr)
        return 1
    from playwright.sync_api import sync_playwright

    width, height = (int(v) for v in args.size.split("x"))
    router = Router()
    port = free_port()
    procs = [run_service("eyes", router.endpoint),
             run_service("eye-renderer", router.endpoint, "--port", str(port), "--no-browser")]
    node: Node | None = None
    try:
        wait_port(port, 30)
        node = Node("bench", connect=[router.endpoint])
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(f"http://127.0.0.1:{port}/eyes?eye=both")
            page.wait_for_function("window.eyes && window.eyes.connected", timeout=20_000)
            print(f"Chromium {browser.version}, headless, page {width}x{height}, both eyes, "
                  "blinking and saccading")

            page.evaluate("window.eyes.frameIntervals.length = 0; "
                          "window.eyes.drawTimes.length = 0")
            time.sleep(args.seconds)  # the measurement window itself
            intervals = page.evaluate("window.eyes.frameIntervals")
            draws = page.evaluate("window.eyes.drawTimes")
            fps = 1000.0 / statistics.mean(intervals)
            figures("frame time (rAF interval)", intervals)
            figures("update+draw per frame", draws)
            met = "met" if percentile(intervals, 0.95) < 17 else "NOT met"
            print(f"{'frames per second':<44} {fps:7.1f}   (p95 frame time < 17 ms: {met})")

            direction = node.publisher(keys.EYES_DIRECTION)
            control = node.publisher(keys.EYE_CONTROL)
            # Discovery: wait until the page follows this publisher at all.
            retry_until(lambda: direction.put(m.EyesDirection(stamp_ns=1, yaw=5, pitch=0))
                        or page.evaluate("window.eyes.target.yaw") == 5, 20, 0.1, "page ready")

            def send_direction(stamp: int, yaw: float) -> None:
                direction.put(m.EyesDirection(stamp_ns=stamp, yaw=yaw, pitch=0.0))

            def send_control(stamp: int, yaw: float) -> None:
                control.put(m.EyeControl(stamp_ns=stamp, yaw=math.radians(yaw), pitch=0.0,
                                         target_distance_cm=100))

            to_page, to_frame = measure_latency(page, args.count, args.rate, send_direction)
            figures("eyes/direction -> page (WebSocket)", to_page)
            figures("eyes/direction -> pupil moving (frame)", to_frame)
            to_page, to_frame = measure_latency(page, args.count, args.rate, send_control)
            figures("eyes/control -> driver -> page", to_page)
            figures("eyes/control -> driver -> pupil moving", to_frame)
            met = "met" if percentile(to_frame, 0.95) < 30 else "NOT met"
            print(f"(target direction -> page < 30 ms: {met} at p95 incl. the driver)")
            browser.close()
    finally:
        if node is not None:
            node.close()
        for proc in procs:
            proc.stop()
        router.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
