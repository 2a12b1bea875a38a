"""Whole-robot benchmark: latencies end to end, CPU and memory of every service.

Starts a router and the services `buddybot up --sim` starts (its launch plan,
with the same command lines: simulated camera at 30 frames/s, simulated radar
with a visitor who comes and goes) as separate processes, then measures for
`--seconds` the gaze latency (capture -> `eyes/direction`, split by hop), the
presence latency (the sensor data that brought someone after nobody, as
`people/state` stamps it -> the eyes awake (the first expression after it
other than EYE_SLEEP/EYE_SLEEPY), by sensor: a radar frame, or a
camera capture when the face came first) and the CPU
and memory of each process. `--dashboard remote|browser` also asks whether
an open dashboard page slows the robot, in alternating windows with the
page closed and open.

    .venv/bin/python benchmarks/robot.py [--seconds 60] [--fps 30]
        [--dashboard remote|browser] [--windows 4]

Method in full: docs/dashboard.md, 'Method of benchmarks/robot.py'.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import shutil
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from tempfile import mkdtemp
from typing import Any

import psutil
import results
from common import percentile

from buddybot import cli
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.controller.events import people_changed
from buddybot.runtime.node import Node
from buddybot.runtime.service import resolve
from buddybot.sdk.persons import person_from
from buddybot.supervisor.launch import plan_up, service_argv
from buddybot.tools.testing import (
    Collector,
    Process,
    Router,
    free_port,
    retry_until,
    wait_port,
)

SETTLE_S = 2.0
"""Left out at the start of each window: the page connecting or going away."""
ASLEEP = frozenset({m.ExpressionAction.EYE_SLEEP, m.ExpressionAction.EYE_SLEEPY})


class BrowserPage:
    """The dashboard in a headless Chromium, kept running; `open` loads the page,
    `close` goes to about:blank (a fresh browser per window would measure its start)."""

    def __init__(self, stack: contextlib.ExitStack, port: int) -> None:
        from playwright.sync_api import sync_playwright

        path = shutil.which("chromium")
        if path is None:
            raise SystemExit("--dashboard browser needs Debian's chromium (scripts/chromium.sh)")
        before = {c.pid for c in psutil.Process().children(recursive=True)}
        pw = stack.enter_context(sync_playwright())
        browser = pw.chromium.launch(executable_path=path, args=[
            "--no-sandbox", "--disable-gpu", "--disable-background-networking"])
        stack.callback(browser.close)
        self.page = browser.new_page(viewport={"width": 1280, "height": 800})
        self.url = f"http://127.0.0.1:{port}/"
        self.procs = [c for c in psutil.Process().children(recursive=True)
                      if c.pid not in before and "chrom" in c.name()]
        self.received = [0, 0]

    def open(self) -> None:
        self.page.goto(self.url)
        self.page.wait_for_function(
            "document.getElementById('conn').textContent === 'on the bus'", timeout=60_000)
        self.page.wait_for_function("window.dash.image !== null", timeout=60_000)

    def close(self) -> None:
        counts = self.page.evaluate("[window.dash.counts.images, window.dash.counts.messages]")
        self.received[0] += counts[0]
        self.received[1] += counts[1]
        self.page.goto("about:blank")


class RemotePage:
    """benchmarks/remote_page.py, started for each open window and stopped after it."""

    def __init__(self, dash_port: int, eye_port: int) -> None:
        self.argv = [sys.executable, str(Path(__file__).with_name("remote_page.py")),
                     "--dashboard-port", str(dash_port), "--eye-port", str(eye_port)]
        self.proc: subprocess.Popen[str] | None = None
        self.procs: list[psutil.Process] = []
        self.received = [0, 0]

    def open(self) -> None:
        self.proc = subprocess.Popen(self.argv, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        if self.proc.stdout.readline().strip() != "reading":
            raise SystemExit("the remote page reader did not start")
        self.procs = [psutil.Process(self.proc.pid)]

    def close(self) -> None:
        if self.proc is None:
            return
        self.proc.send_signal(signal.SIGINT)
        out, _ = self.proc.communicate(timeout=30)
        got = json.loads(out.strip().splitlines()[-1])
        self.received[0] += got["images"]
        self.received[1] += got["messages"]
        self.proc = None


def up_sim(config: str | None, eye_port: int, dash_port: int,
           endpoint: str) -> dict[str, list[str]]:
    """{service: its command line} of what `buddybot up --sim --no-browser` starts
    (with `--config`), its pages on the given ports, connected to `endpoint`."""
    argv = ["up", "--sim", "--no-browser", "--eye-port", str(eye_port),
            "--dashboard-port", str(dash_port), *(("--config", config) if config else ())]
    ctx = resolve(cli.build_parser().parse_args(argv), "up")
    plan = plan_up(ctx)
    return {e.name: service_argv(e.name, ctx, endpoint, plan.service_args.get(e.name))
            for e in plan.entries}


def windows(total_s: float, pairs: int) -> Iterator[tuple[bool, float]]:
    """(page open?, seconds) for each window: closed, open, closed, open, ..."""
    each = total_s / (2 * pairs)
    for _ in range(pairs):
        yield False, each
        yield True, each


def summary(values: list[float]) -> str:
    if not values:
        return "no samples"
    return (f"median {statistics.median(values):.1f} ms, p95 {percentile(values, 0.95):.1f} ms,"
            f" n={len(values)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--sim-speed", type=float, default=3.0,
                        help="radar scenario speed (more visits per minute)")
    parser.add_argument("--config", help="robot config file for every service")
    parser.add_argument("--dashboard", choices=("remote", "browser"),
                        help="also run the dashboard and compare the page closed and open")
    parser.add_argument("--windows", type=int, default=4,
                        help="with --dashboard: pairs of windows (page closed, page open)")
    args = parser.parse_args()
    log_dir = Path(mkdtemp(prefix="buddybot-bench-"))
    router = Router(log_dir=log_dir)
    eye_port = free_port()
    dash_port = free_port()
    services = up_sim(args.config, eye_port, dash_port, router.endpoint)
    bench_options: dict[str, tuple[str, ...]] = {
        "audio-player": ("--backend", "null"),
        "camera": ("--fps", str(args.fps), "--sim-speed", str(args.sim_speed)),
        "radar-bridge": ("--sim-speed", str(args.sim_speed)),
        "sim": ("--sim-speed", str(args.sim_speed)),
    }
    if args.dashboard and "dashboard" not in services:
        raise SystemExit("--dashboard: the config leaves the dashboard out of `up`")
    procs: dict[str, Process] = {}
    probe = Node("bench-probe", connect=[router.endpoint])
    stack = contextlib.ExitStack()
    page: BrowserPage | RemotePage | None = None
    # Samples go to the side of the window they arrive in; None while settling.
    gaze: dict[bool, list[float]] = {False: [], True: []}
    side: list[bool | None] = [False if args.dashboard else None]
    cpu_by_side: dict[bool, dict[str, float]] = {False: {}, True: {}}
    try:
        for name, argv in services.items():
            procs[name] = Process([*argv, *bench_options.get(name, ())], name, log_dir)
        retry_until(lambda: set(services) <= set(probe.node_instances()), 90, 0.5,
                    "all nodes up")
        gaze_ms: list[float] = []
        awake_ms: dict[str, list[float]] = {"RADAR": [], "CAMERA": []}
        """Arrival -> the eyes awake, by the sensor that showed the person first."""
        hops: dict[str, list[float]] = {"camera/front/face": [], "eyes/control": []}

        def on_direction(msg: m.EyesDirection, _key: str) -> None:
            latency = (time.time_ns() - msg.stamp_ns) / 1e6
            gaze_ms.append(latency)
            if side[0] is not None:
                gaze[side[0]].append(latency)

        def hop(name: str) -> Callable[[Any, str], None]:
            def on(msg: Any, _key: str) -> None:
                hops[name].append((time.time_ns() - msg.stamp_ns) / 1e6)
            return on

        arrived: list[tuple[int, str] | None] = [None]
        """The stamp of the people/state that brought someone in range and the sensor
        that showed them, until the eyes wake."""
        present = [False]
        shown = [m.ExpressionAction.EYE_SLEEP]
        """The expression on the eyes now."""

        def on_people(msg: m.PeopleState, _key: str) -> None:
            change = people_changed([person_from(p) for p in msg.people])  # the controller's
            # An arrival after nobody was there, to sleeping eyes (a person held and
            # shown again is no arrival; one who comes while the robot is still awake
            # and alone after the last visit finds the eyes open).
            if change.in_range and not present[0] and shown[0] in ASLEEP:
                who = next(p for p in msg.people if p.id == change.person_id)
                arrived[0] = (msg.stamp_ns, "CAMERA" if who.seen_by == "CAMERA" else "RADAR")
            elif not (change.in_range or change.held):
                arrived[0] = None
            present[0] = change.in_range or change.held

        def on_expression(msg: m.ScreenExpression, _key: str) -> None:
            shown[0] = msg.action
            first = arrived[0]
            if msg.action not in ASLEEP and first is not None:
                awake_ms[first[1]].append((time.time_ns() - first[0]) / 1e6)
                arrived[0] = None

        Collector(probe, keys.EYES_DIRECTION).wait_for(timeout=60, what="gaze")
        if args.dashboard == "browser":
            wait_port(dash_port, 30)
            page = BrowserPage(stack, dash_port)
        elif args.dashboard == "remote":
            wait_port(dash_port, 30)
            page = RemotePage(dash_port, eye_port)
            stack.callback(page.close)
        time.sleep(3.0)  # warm-up: detector models loaded, caches filled
        probe.subscribe(keys.EYES_DIRECTION, on_direction)
        probe.subscribe(keys.FACE, hop("camera/front/face"), camera="front")
        probe.subscribe(keys.EYE_CONTROL, hop("eyes/control"))
        probe.subscribe(keys.PEOPLE_STATE, on_people, history=False)
        probe.subscribe(keys.EXPRESSION, on_expression, history=False)

        ps = {name: psutil.Process(p.pid) for name, p in procs.items()}
        ps["router"] = psutil.Process(router.pid)
        for p in ps.values():
            p.cpu_percent(None)
        rss: dict[str, list[float]] = {name: [] for name in ps}
        started = time.monotonic()

        def sample_for(seconds: float) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                time.sleep(min(1.0, max(0.0, end - time.monotonic())))
                for name, p in ps.items():
                    rss[name].append(p.memory_info().rss / 2**20)

        if page is None:
            sample_for(args.seconds)
        else:
            for is_open, seconds in windows(args.seconds, args.windows):
                side[0] = None
                if is_open:
                    page.open()
                sample_for(SETTLE_S)
                # Own psutil objects: cpu_percent(None) counts from the last call on
                # the same object, and `ps` keeps counting the whole run.
                window_ps = {name: psutil.Process(p.pid) for name, p in ps.items()}
                window_ps.update({f"page{i}": p for i, p in enumerate(page.procs)})
                for p in window_ps.values():
                    with contextlib.suppress(psutil.Error):
                        p.cpu_percent(None)
                side[0] = is_open
                sample_for(max(0.0, seconds - SETTLE_S))
                side[0] = None
                share = cpu_by_side[is_open]
                for name, p in window_ps.items():
                    with contextlib.suppress(psutil.Error):  # a helper process may have exited
                        key = "page" if name.startswith("page") else name
                        share[key] = share.get(key, 0.0) + p.cpu_percent(None) / args.windows
                if is_open:
                    page.close()
        elapsed = time.monotonic() - started
        cpu = {name: p.cpu_percent(None) for name, p in ps.items()}
    finally:
        stack.close()
        probe.close()
        for proc in procs.values():
            proc.stop()
        router.stop()

    print(f"whole robot, {args.seconds:.0f} s, camera {args.fps:.0f} fps (simulated), "
          f"radar visit x{args.sim_speed:g}"
          + (f", dashboard page {args.dashboard}, {args.windows} pairs of windows"
             if args.dashboard else "") + f"; logs in {log_dir}")
    if gaze_ms:
        print(f"gaze latency capture -> eyes/direction: {summary(gaze_ms)} "
              f"({len(gaze_ms) / elapsed:.1f}/s)")
        for name, values in hops.items():
            if values:
                print(f"  capture -> {name}: {summary(values)}")
    else:
        print("gaze latency: no eyes/direction received")
    if page is not None:
        open_s = args.seconds / 2  # received while open, settling included
        print(f"page open: received {page.received[0]} images ({page.received[0] / open_s:.1f}"
              f"/s) and {page.received[1]} dashboard messages")
        print(f"gaze latency, page closed: {summary(gaze[False])}")
        print(f"gaze latency, page open:   {summary(gaze[True])}")
        if gaze[False] and gaze[True]:
            closed95 = percentile(gaze[False], 0.95)
            open95 = percentile(gaze[True], 0.95)
            print(f"p95 open / closed: {open95 / closed95:.3f} "
                  f"({(open95 / closed95 - 1) * 100:+.1f} %; target within +10 %)")
        print(f"{'CPU % of a core':<22}{'closed':>8}{'open':>8}")
        for name in ("dashboard", "eye-renderer", "page"):
            print(f"  {name:<20}{cpu_by_side[False].get(name, 0.0):>8.1f}"
                  f"{cpu_by_side[True].get(name, 0.0):>8.1f}")
        robot = [n for n in ps if n not in ("dashboard", "eye-renderer")]
        print(f"  {'the rest (router too)':<20}"
              f"{sum(cpu_by_side[False].get(n, 0.0) for n in robot):>8.1f}"
              f"{sum(cpu_by_side[True].get(n, 0.0) for n in robot):>8.1f}")
    for sensor, what in (("RADAR", "radar frame"), ("CAMERA", "camera capture")):
        got = awake_ms[sensor]
        if got:
            print(f"presence latency {what} -> people/state -> eyes/expression AWAKE: "
                  f"median {statistics.median(got):.1f} ms, max {max(got):.1f} ms, "
                  f"n={len(got)}")
    if not any(awake_ms.values()):
        print("presence latency: the eyes never woke for an arrival (run longer)")
    print(f"{'process':<16}{'CPU % of a core':>16}{'RSS MB (max)':>14}{'RSS growth kB':>15}")
    for name in ps:
        print(f"{name:<16}{cpu[name]:>16.1f}{max(rss[name] or [0]):>14.1f}"
              f"{rss_growth_kb(rss[name]):>15.0f}")
    total_rss = sum(max(v or [0]) for v in rss.values())
    print(f"{'total':<16}{sum(cpu.values()):>16.1f}{total_rss:>14.1f}"
          f"{sum(rss_growth_kb(v) for v in rss.values()):>15.0f}")


def rss_growth_kb(samples_mb: list[float]) -> float:
    """The soak figure: the median RSS of the run's last fifth minus that of its
    first fifth (one sample a second), so a leak shows and a spike does not.
    With `--dashboard` the last window has the page open and the first not, so
    the dashboard's figure then holds an open page's working set (about 50 MB:
    frames and their buffers), not a leak; soak it with the page open throughout."""
    fifth = len(samples_mb) // 5
    if fifth < 1:
        return 0.0
    return (statistics.median(samples_mb[-fifth:]) - statistics.median(samples_mb[:fifth])) * 1024


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
