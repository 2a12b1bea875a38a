"""Eyes benchmark: animation frame time and published direction -> pupil moving on the page.

Starts a router, `buddybot run eyes` and `buddybot run eye-renderer
--no-browser` as processes (as in production) and opens the page in
Debian's headless Chromium through Playwright. Prints, per eye style and
page size, the frame time (target: 60 fps, p95 < 16.7 ms), the page's own
update+draw cost and Chromium's CPU; the latency from a published
`eyes/direction`, and from `controller/eye_control` through the driver, to the first
frame drawn with the new target (target: median < 20 ms); and, under
attack (stuck WebSocket clients and a flood), how old the page's gaze is.

    .venv/bin/python benchmarks/eyes.py [--style both] [--size 800x480,1920x1080]
        [--seconds 5] [--count 200] [--stuck 500] [--flood 20]
    .venv/bin/python benchmarks/eyes.py --flood-only      # just the attack

Method in full: docs/eyes.md, 'Method of benchmarks/eyes.py'.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import socket
import statistics
import sys
import threading
import time
import urllib.request
from typing import Any

import psutil
import results
from common import CHROMIUM_ARGS, percentile

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Router,
    free_port,
    retry_until,
    run_service,
    stuck_websocket,
    wait_port,
)

FRAME_MS = 16.67
"""One display frame at 60 Hz."""
TIMER_MS = 0.2
"""performance.now() resolution in Chromium (0.1 ms) on both ends of an interval."""


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


def stuck_page(port: int) -> socket.socket | None:
    """A client that does the handshake and then never reads; None when the
    server refused the connection outright."""
    try:
        return stuck_websocket(port)[0]
    except OSError:
        return None


class Flood:
    """`eyes/control` (or `eyes/direction` straight to the renderer) as fast as
    one thread can publish it (stamp = now)."""

    def __init__(self, node: Node, direct: bool) -> None:
        self._direct = direct
        self._pub = node.publisher(keys.EYES_DIRECTION if direct else keys.BEHAVIOUR_GAZE)
        self._stop = threading.Event()
        self.count = 0
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            yaw = (self.count % 40) - 20.0
            if self._direct:
                self._pub.put(m.EyesDirection(stamp_ns=m.now_ns(), yaw=yaw, pitch=0.0))
            else:
                self._pub.put(m.EyeControl(stamp_ns=m.now_ns(), yaw=math.radians(yaw),
                                           pitch=0.0, target_distance_cm=100))
            self.count += 1

    def run_for(self, seconds: float, during: Any) -> None:
        self._thread.start()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            during()
        self._stop.set()
        self._thread.join(30)


def attack(page: Any, node: Node, port: int, renderer_pid: int, stuck_n: int,
           seconds: float, direct: bool) -> None:
    """Stuck pages plus a control flood while the real page is measured."""
    proc = psutil.Process(renderer_pid)
    rss0 = proc.memory_info().rss / 2**20
    t0 = time.monotonic()
    socks = [stuck_page(port) for _ in range(stuck_n)]
    opened = sum(1 for s in socks if s is not None)
    print(f"{stuck_n} never-reading WebSocket clients: {opened} handshakes completed in "
          f"{time.monotonic() - t0:.1f} s")
    page.evaluate("window.eyes.latency.length = 0")
    messages0 = page.evaluate("window.eyes.stats.messages")
    health_ms: list[float] = []
    health_fail = 0
    rss: list[float] = []

    def probe() -> None:
        nonlocal health_fail
        start = time.perf_counter()
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=30) as r:
                r.read()
            health_ms.append((time.perf_counter() - start) * 1000)
        except OSError:
            health_fail += 1
        rss.append(proc.memory_info().rss / 2**20)
        time.sleep(0.25)   # sampling period, not synchronisation

    flood = Flood(node, direct)
    flood_start_ms = time.time() * 1000
    flood.run_for(seconds, probe)
    ages = [rec["recv_ms"] - float(rec["stamp_ns"]) / 1e6
            for rec in page.evaluate("window.eyes.latency")
            if float(rec["stamp_ns"]) / 1e6 >= flood_start_ms]
    received = page.evaluate("window.eyes.stats.messages") - messages0
    topic = "eyes/direction" if direct else "controller/eye_control"
    print(f"flood: {flood.count} {topic} in {seconds:.0f} s "
          f"({flood.count / seconds:.0f}/s); the real page got {received} messages")
    if ages:
        figures("gaze age on the real page during the flood", ages)
    else:
        print(f"{'gaze age on the real page during the flood':<44} no gaze arrived at all")
    if health_ms:
        figures("/healthz during the flood", health_ms)
    print(f"{'/healthz failures (30 s timeout)':<44} {health_fail}")
    print(f"{'renderer RSS':<44} before {rss0:.0f} MB, peak {max(rss):.0f} MB, "
          f"end {rss[-1]:.0f} MB")
    # Recovery: a distinct gaze published after the flood reaches the page.
    direction = node.publisher(keys.EYES_DIRECTION)
    start = time.monotonic()
    try:
        retry_until(lambda: direction.put(m.EyesDirection(stamp_ns=m.now_ns(), yaw=33.0,
                                                          pitch=0.0))
                    or page.evaluate("window.eyes.target.yaw") == 33, 120, 0.05,
                    "gaze after the flood")
        print(f"{'gaze after the flood -> page':<44} {(time.monotonic() - start) * 1000:7.0f} ms")
    except TimeoutError:
        print(f"{'gaze after the flood -> page':<44} not within 120 s")
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=30) as r:
            info = json.loads(r.read())
        if "samples" in info:
            print(f"{'renderer got from the bus':<44} {info['samples']} samples, forwarded "
                  f"{info['messages']} (the rest coalesced)")
        print(f"{'pages':<44} connected {info['clients']} "
              f"(max {info.get('max_pages', '-')}), refused {info.get('refused', '-')}, "
              f"dropped {info.get('dropped', '-')}; RSS now "
              f"{proc.memory_info().rss / 2**20:.0f} MB")
    except OSError as exc:
        print(f"{'pages':<44} /healthz failed: {exc}")
    for sock in socks:
        if sock is not None:
            sock.close()


def chromium_processes() -> list[psutil.Process]:
    """Every Chromium process Playwright started for us (browser, GPU, renderers)."""
    found = []
    for proc in psutil.Process().children(recursive=True):
        try:
            if "chrom" in proc.name().lower():
                found.append(proc)
        except psutil.Error:
            continue
    return found


def cpu_seconds(procs: list[psutil.Process]) -> float:
    total = 0.0
    for proc in procs:
        try:
            times = proc.cpu_times()
            total += times.user + times.system
        except psutil.Error:
            continue
    return total


def measure_frames(page: Any, seconds: float) -> tuple[list[float], list[float], float]:
    """rAF intervals and per-frame update+draw costs (ms) over `seconds` of the page
    blinking and saccading by itself, and Chromium's CPU meanwhile (% of one core)."""
    procs = chromium_processes()
    page.evaluate("window.eyes.frameIntervals.length = 0; window.eyes.drawTimes.length = 0")
    cpu0, t0 = cpu_seconds(procs), time.monotonic()
    time.sleep(seconds)  # the measurement window itself
    cpu = 100.0 * (cpu_seconds(procs) - cpu0) / (time.monotonic() - t0)
    return (page.evaluate("window.eyes.frameIntervals"), page.evaluate("window.eyes.drawTimes"),
            cpu)


def bench_style(browser: Any, node: Node, router: Router, style: str, sizes: list[str],
                args: argparse.Namespace, summary: list[str]) -> None:
    """Frame time, page CPU and direction -> drawn latency of one style at each size."""
    port = free_port()
    renderer = run_service("eye-renderer", router.endpoint, "--port", str(port), "--no-browser",
                           "--style", style)
    try:
        wait_port(port, 30)
        direction = node.publisher(keys.EYES_DIRECTION)
        control = node.publisher(keys.BEHAVIOUR_GAZE)
        for size in sizes:
            width, height = (int(v) for v in size.split("x"))
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(f"http://127.0.0.1:{port}/eyes?eye=both")
            page.wait_for_function("window.eyes && window.eyes.ready", timeout=20_000)
            print(f"\n--- style {style}, page {width}x{height}, both eyes, blinking and "
                  "saccading")
            intervals, draws, cpu = measure_frames(page, args.seconds)
            fps = 1000.0 / statistics.mean(intervals)
            figures("frame time (rAF interval)", intervals)
            figures("update+draw per frame", draws)
            # rAF intervals are whole display frames (16.67 ms at 60 Hz) read with
            # Chromium's 0.1 ms timer: p95 at one frame (+ that resolution) means
            # no frame was dropped, one frame more would be 33.3 ms.
            met = "met" if percentile(intervals, 0.95) <= FRAME_MS + TIMER_MS else "NOT met"
            print(f"{'frames per second':<44} {fps:7.1f}   (p95 frame time within one "
                  f"60 Hz frame, {FRAME_MS} ms + {TIMER_MS} ms timer resolution: {met})")
            print(f"{'Chromium CPU (all its processes)':<44} {cpu:7.1f} % of one core")
            # Discovery: wait until the page follows this publisher at all.
            def follows(page: Any = page) -> bool:
                direction.put(m.EyesDirection(stamp_ns=1, yaw=5, pitch=0))
                return bool(page.evaluate("window.eyes.target.yaw") == 5)

            retry_until(follows, 20, 0.1, "page ready")

            def send_direction(stamp: int, yaw: float) -> None:
                direction.put(m.EyesDirection(stamp_ns=stamp, yaw=yaw, pitch=0.0))

            def send_control(stamp: int, yaw: float) -> None:
                control.put(m.EyeControl(stamp_ns=stamp, yaw=math.radians(yaw), pitch=0.0,
                                         target_distance_cm=100))

            to_page, to_frame = measure_latency(page, args.count, args.rate, send_direction)
            figures("eyes/direction -> page (WebSocket)", to_page)
            figures("eyes/direction -> drawn (frame)", to_frame)
            to_page_c, to_frame_c = measure_latency(page, args.count, args.rate, send_control)
            figures("controller/eye_control -> driver -> page", to_page_c)
            figures("controller/eye_control -> driver -> drawn", to_frame_c)
            met = "met" if statistics.median(to_frame) < 20 else "NOT met"
            print(f"(target direction -> drawn median < 20 ms: {met})")
            summary.append(
                f"{style:<8} {size:>9}  frame p50 {statistics.median(intervals):5.1f} ms  "
                f"p95 {percentile(intervals, 0.95):5.1f} ms  draw p95 "
                f"{percentile(draws, 0.95):5.2f} ms  direction->drawn median "
                f"{statistics.median(to_frame):5.1f} ms  Chromium CPU {cpu:5.1f} %")
            if args.flood > 0 and style == args.styles[-1] and size == sizes[-1]:
                attack(page, node, port, renderer.pid, args.stuck, args.flood,
                       args.flood_direction)
            page.close()
    finally:
        renderer.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="frame-time window")
    parser.add_argument("--count", type=int, default=200, help="gaze targets to publish")
    parser.add_argument("--rate", type=float, default=20.0, help="gaze targets per second")
    parser.add_argument("--size", default="800x480,1920x1080",
                        help="page sizes, comma-separated (a small HDMI eye screen, full HD)")
    parser.add_argument("--style", default="both", choices=["glow", "eyeball", "both"],
                        help="eye style(s) to measure")
    parser.add_argument("--stuck", type=int, default=500,
                        help="never-reading WebSocket clients during the attack")
    parser.add_argument("--flood", type=float, default=20.0,
                        help="seconds of eyes/control flood (0 = no attack)")
    parser.add_argument("--flood-only", action="store_true", help="skip frame time and latency")
    parser.add_argument("--flood-direction", action="store_true",
                        help="flood eyes/direction straight to the renderer (no driver)")
    args = parser.parse_args()
    args.styles = ["glow", "eyeball"] if args.style == "both" else [args.style]
    sizes = args.size.split(",")
    chromium = shutil.which("chromium")
    if chromium is None:
        print("chromium not installed (scripts/chromium.sh installs it)", file=sys.stderr)
        return 1
    from playwright.sync_api import sync_playwright

    router = Router()
    driver = run_service("eyes", router.endpoint)
    node: Node | None = None
    summary: list[str] = []
    try:
        node = Node("bench", connect=[router.endpoint])
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            print(f"Chromium {browser.version}, headless, software rendering (--disable-gpu)")
            try:
                if args.flood_only:
                    args.styles, sizes, args.seconds, args.count = args.styles[-1:], sizes[:1], \
                        0.5, 20
                for style in args.styles:
                    bench_style(browser, node, router, style, sizes, args, summary)
            finally:
                browser.close()
    finally:
        if node is not None:
            node.close()
        driver.stop()
        router.stop()
    print("\nsummary (targets: frame p95 one 60 Hz frame (16.7 ms), direction->drawn "
          "median < 20 ms)")
    for line in summary:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
