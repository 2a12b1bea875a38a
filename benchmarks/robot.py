"""Whole-robot benchmark: latencies end to end, CPU and memory of every service.

Starts a router and all nine services (simulated camera at 30 frames/s,
simulated radar with a visitor who comes and goes) as separate processes,
then for `--seconds`:

* gaze latency: time from an image's capture (`stamp_ns`, kept by the face,
  eye control and direction) to the `eyes/direction` sample arriving here,
  and to each hop on the way (face position, eye control), so the total
  can be split between the detector, the controller and the eyes;
* presence latency: time from the radar frame (`stamp_ns` kept by presence
  and expression) to `eyes/expression` EYE_AWAKE arriving here; entering
  needs no hold, so this is the pipeline's own latency;
* CPU (% of one core) and resident memory of each process and in total.

`--dashboard` also starts the dashboard service and keeps its page open in
a headless Chromium (Debian's, through Playwright) for the whole run, so
the gaze latency with and without a page watching can be compared; the
dashboard's and the browser's CPU are reported too.

    .venv/bin/python benchmarks/robot.py [--seconds 60] [--fps 30] [--dashboard]
"""

from __future__ import annotations

import argparse
import contextlib
import shutil
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from tempfile import mkdtemp
from typing import Any

import psutil
from common import percentile

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.node import Node
from buddybot.core.testing import (
    Collector,
    Process,
    Router,
    free_port,
    retry_until,
    run_service,
    wait_port,
)


@contextlib.contextmanager
def dashboard_page(port: int) -> Any:
    """The dashboard page open in a headless Chromium until the block ends; yields
    the browser's processes (for their CPU)."""
    from playwright.sync_api import sync_playwright

    path = shutil.which("chromium")
    if path is None:
        raise SystemExit("--dashboard needs Debian's chromium (scripts/chromium.sh)")
    before = {c.pid for c in psutil.Process().children(recursive=True)}
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=path, args=[
            "--no-sandbox", "--disable-gpu", "--disable-background-networking"])
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_function(
                "document.getElementById('conn').textContent === 'on the bus'", timeout=60_000)
            page.wait_for_function("window.dash.image !== null", timeout=60_000)
            procs = [c for c in psutil.Process().children(recursive=True)
                     if c.pid not in before and "chrom" in c.name()]
            yield procs, page
        finally:
            browser.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--sim-speed", type=float, default=3.0,
                        help="radar scenario speed (more visits per minute)")
    parser.add_argument("--config", help="robot config file for every service")
    parser.add_argument("--dashboard", action="store_true",
                        help="also run the dashboard with its page open in headless Chromium")
    args = parser.parse_args()
    log_dir = Path(mkdtemp(prefix="buddybot-bench-"))
    router = Router(log_dir=log_dir)
    services: dict[str, tuple[str, ...]] = {
        "audio-player": ("--backend", "null"),
        "audio": (),
        "eyes": (),
        "eye-renderer": ("--no-browser", "--port", str(free_port())),
        "controller": (),
        "face-detector": (),
        "radar-presence": (),
        "camera": ("--sim", "--fps", str(args.fps)),
        "radar-bridge": ("--sim", "--sim-scenario", "visit", "--sim-speed", str(args.sim_speed)),
    }
    dash_port = free_port()
    if args.dashboard:
        services["dashboard"] = ("--port", str(dash_port))
    procs: dict[str, Process] = {}
    probe = Node("bench-probe", connect=[router.endpoint])
    page = contextlib.ExitStack()
    browser_procs: list[psutil.Process] = []
    page_frames: tuple[int, int] | None = None
    page_seconds = 1.0
    try:
        common = ("--config", args.config) if args.config else ()
        for name, extra in services.items():
            procs[name] = run_service(name, router.endpoint, *common, *extra, log_dir=log_dir)
        retry_until(lambda: set(services) <= set(probe.node_instances()), 90, 0.5,
                    "all nodes up")
        gaze_ms: list[float] = []
        awake_ms: list[float] = []
        hops: dict[str, list[float]] = {"camera/front/face": [], "eyes/control": []}

        def on_direction(msg: m.EyesDirection, _key: str) -> None:
            gaze_ms.append((time.time_ns() - msg.stamp_ns) / 1e6)

        def hop(name: str) -> Callable[[Any, str], None]:
            def on(msg: Any, _key: str) -> None:
                hops[name].append((time.time_ns() - msg.stamp_ns) / 1e6)
            return on

        def on_expression(msg: m.ScreenExpression, _key: str) -> None:
            if msg.action == m.ExpressionAction.EYE_AWAKE:
                awake_ms.append((time.time_ns() - msg.stamp_ns) / 1e6)

        Collector(probe, keys.EYES_DIRECTION).wait_for(timeout=60, what="gaze")
        if args.dashboard:
            wait_port(dash_port, 30)
            browser_procs, dash = page.enter_context(dashboard_page(dash_port))
            counts = dash.evaluate("[window.dash.counts.images, window.dash.counts.messages]")
            counted_from = time.monotonic()
        time.sleep(3.0)  # warm-up: detector models loaded, caches filled
        probe.subscribe(keys.EYES_DIRECTION, on_direction)
        probe.subscribe(keys.FACE, hop("camera/front/face"), camera="front")
        probe.subscribe(keys.EYE_CONTROL, hop("eyes/control"))
        probe.subscribe(keys.EXPRESSION, on_expression, history=False)

        ps = {name: psutil.Process(p.pid) for name, p in procs.items()}
        ps["router"] = psutil.Process(router.pid)
        for p in [*ps.values(), *browser_procs]:
            p.cpu_percent(None)
        rss: dict[str, list[float]] = {name: [] for name in ps}
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            time.sleep(1.0)
            for name, p in ps.items():
                rss[name].append(p.memory_info().rss / 2**20)
        cpu = {name: p.cpu_percent(None) for name, p in ps.items()}
        browser_cpu = 0.0
        for p in browser_procs:
            with contextlib.suppress(psutil.Error):  # a helper process may have exited
                browser_cpu += p.cpu_percent(None)
        if args.dashboard:
            now = dash.evaluate("[window.dash.counts.images, window.dash.counts.messages]")
            page_frames = (now[0] - counts[0], now[1] - counts[1])
            page_seconds = time.monotonic() - counted_from
    finally:
        page.close()
        probe.close()
        for proc in procs.values():
            proc.stop()
        router.stop()

    print(f"whole robot, {args.seconds:.0f} s, camera {args.fps:.0f} fps (simulated), "
          f"radar visit x{args.sim_speed:g}, dashboard page "
          f"{'open' if args.dashboard else 'not open'}; logs in {log_dir}")
    if page_frames is not None:
        print(f"dashboard page received {page_frames[0]} images and {page_frames[1]} messages "
              f"in {page_seconds:.0f} s ({page_frames[0] / page_seconds:.1f} images/s)")
    if gaze_ms:
        print(f"gaze latency capture -> eyes/direction: median {statistics.median(gaze_ms):.1f} ms,"
              f" p95 {percentile(gaze_ms, 0.95):.1f} ms, n={len(gaze_ms)} "
              f"({len(gaze_ms) / args.seconds:.1f}/s)")
        for name, values in hops.items():
            if values:
                print(f"  capture -> {name}: median {statistics.median(values):.1f} ms, "
                      f"p95 {percentile(values, 0.95):.1f} ms, n={len(values)}")
    else:
        print("gaze latency: no eyes/direction received")
    if awake_ms:
        print(f"presence latency radar frame -> eyes/expression AWAKE: "
              f"median {statistics.median(awake_ms):.1f} ms, max {max(awake_ms):.1f} ms, "
              f"n={len(awake_ms)}")
    else:
        print("presence latency: no EYE_AWAKE seen (run longer)")
    print(f"{'process':<16}{'CPU % of a core':>16}{'RSS MB (max)':>14}")
    for name in ps:
        print(f"{name:<16}{cpu[name]:>16.1f}{max(rss[name] or [0]):>14.1f}")
    if browser_procs:
        print(f"{'chromium (page)':<16}{browser_cpu:>16.1f}{'':>14}")
    total_rss = sum(max(v or [0]) for v in rss.values())
    print(f"{'total':<16}{sum(cpu.values()):>16.1f}{total_rss:>14.1f}")


if __name__ == "__main__":
    main()
