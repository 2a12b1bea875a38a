"""People benchmark: radar frame -> an app's ARRIVED callback; the `people` service's CPU.

    .venv/bin/python benchmarks/people.py [--visits 40] [--cpu-seconds 20] [--fps 30]

1. Arrival latency: a router, `radar-presence` and `people` as processes on
   127.0.0.1, and an SDK program in this process (`Bot.on("ARRIVED", cb)`).
   LD2410 frames are published on `radar/bench/frames` at 10 Hz, like a
   bridge. A visit: the frames switch from "nobody" to "a moving target at
   1.2 m" (the first near frame is put at once, stamped with the put time),
   the program's callback fires on ARRIVED, then the frames say "nobody"
   until LEFT. Latency = callback time - that frame's stamp (same host
   clock): frame -> router -> radar-presence -> router -> people -> router
   -> the SDK's stream thread -> the callback. Both holds are short
   (`--absence-hold-s` 0.2 on radar-presence, `absence_hold_s` 0.2 in
   `[people]`) so a visit takes about a second; entering needs no hold.
2. CPU of `people` with a visitor: radar presence IN_RANGE (latched, once)
   and the followed face on `camera/front/face` at `--fps`, standing about
   1.5 m away with a few centimetres of detector noise (so every frame moves
   the person and `people/state` is republished, as with a real camera).
   CPU = utime + stime of the process (/proc/<pid>/stat, via psutil) over the
   window / wall time.
"""

from __future__ import annotations

import random
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil
import results
from common import host, options, percentile

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import ld2410
from buddybot.radar.convert import report_to_frame
from buddybot.runtime.node import Node
from buddybot.sdk import Bot, Event
from buddybot.tools.testing import Collector, Process, Router, retry_until, run_service

DEVICE = "bench"
FRAME_PERIOD_S = 0.1  # an LD2410 sends ~10 frames/s
HOLD_S = 0.2  # radar-presence's and people's absence holds: short visits


def _frames() -> tuple[m.LD2410TargetDataFrame, m.LD2410TargetDataFrame]:
    """A moving target at 1.2 m, and the same sensor seeing nobody, as the bridge
    converts the sensor's reports."""
    near = report_to_frame(ld2410.Report(1, 120, 50, 0, 0, 120), radar_id=0).frame
    empty = report_to_frame(ld2410.Report(0, 0, 0, 0, 0, 0), radar_id=0).frame
    return near, empty


class Radar:
    """A bridge's output: the current frame every FRAME_PERIOD_S, and `switch`
    to put a new one at once."""

    def __init__(self, node: Node) -> None:
        self._pub = node.publisher(keys.RADAR_FRAMES, device=DEVICE)
        self.near, self.empty = _frames()
        self._frame = self.empty
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-radar", daemon=True)

    def start(self) -> Radar:
        self._thread.start()
        return self

    def _put(self, stamp: int) -> None:
        self._pub.put(m.LD2410TargetDataFrameArray(stamp_ns=stamp, device_id=0,
                                                   sensors=[self._frame]))

    def _run(self) -> None:
        while not self._stop.wait(FRAME_PERIOD_S):
            with self._lock:
                self._put(time.time_ns())

    def switch(self, present: bool, stamp: int) -> None:
        """The new frame at once, stamped `stamp` (taken just before: the put time)."""
        with self._lock:
            self._frame = self.near if present else self.empty
            self._put(stamp)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


class Arrivals:
    """The program's side: the callback's latencies, and waits on ARRIVED / LEFT."""

    def __init__(self) -> None:
        self.latencies_ms: list[float] = []
        self.kinds: list[str] = []
        self.unmatched = 0
        self.expected_stamp = 0
        self._cond = threading.Condition()

    def on_event(self, event: Event) -> None:
        now = time.time_ns()
        with self._cond:
            if event.kind == "ARRIVED" and not event.replayed:
                if event.stamp_ns == self.expected_stamp:
                    self.latencies_ms.append((now - event.stamp_ns) / 1e6)
                else:
                    self.unmatched += 1
            self.kinds.append(event.kind)
            self._cond.notify_all()

    def wait(self, kind: str, count: int, timeout: float) -> None:
        with self._cond:
            if not self._cond.wait_for(lambda: self.kinds.count(kind) >= count, timeout):
                raise TimeoutError(f"no {kind} #{count} within {timeout} s: {self.kinds[-6:]}")


def _people_config(folder: Path, **fields: float) -> str:
    path = folder / "people.toml"
    path.write_text("[people]\n" + "".join(f"{k} = {v}\n" for k, v in fields.items()))
    return str(path)


def _wait_subscribed(probe: Node, node: str, key: str) -> None:
    """Until `node` has declared its subscription to `key` (it may start slowly
    beside a loaded machine)."""
    retry_until(lambda: any(i.node == node and key in i.subscriptions
                            for i in probe.node_infos(1.0)), 60, 0.2, f"{node} on {key}")


def bench_arrival(router: Router, visits: int, folder: Path) -> None:
    config = _people_config(folder, absence_hold_s=HOLD_S)
    procs = [run_service("radar-presence", router.endpoint, "--absence-hold-s", str(HOLD_S)),
             run_service("people", router.endpoint, "--config", config)]
    probe = Node("bench-radar", connect=[router.endpoint])
    arrivals = Arrivals()
    radar: Radar | None = None
    try:
        diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="radar-presence")
        _wait_subscribed(probe, "people", keys.PRESENCE.key())
        _wait_subscribed(probe, "radar-presence", keys.RADAR_FRAMES.wildcard())
        radar = Radar(probe).start()
        diag.wait_for(lambda d: d.level == "OK", 30, "radar-presence: the sensor fresh")
        with Bot.connect(connect=[router.endpoint], timeout=10) as bot:
            bot.on(("ARRIVED", "LEFT"), arrivals.on_event)
            rng = random.Random(24)
            for visit in range(1, visits + 1):
                time.sleep(rng.uniform(0.05, 0.15))  # off the 10 Hz beat of the frames
                arrivals.expected_stamp = stamp = time.time_ns()
                radar.switch(True, stamp)
                arrivals.wait("ARRIVED", visit, 30)
                time.sleep(0.1)  # a visit of a few frames (the pace, not a synchronisation)
                radar.switch(False, time.time_ns())
                arrivals.wait("LEFT", visit, 30)
    finally:
        if radar is not None:
            radar.stop()
        probe.close()
        for proc in procs:
            proc.stop()
    values = arrivals.latencies_ms
    print(f"radar frame put -> SDK callback for ARRIVED (n={len(values)} visits, "
          f"{arrivals.unmatched} unmatched): median {statistics.median(values):.2f} ms, "
          f"p90 {percentile(values, 0.9):.2f} ms, max {max(values):.2f} ms  "
          f"(target: median <= 5 ms)")


class Camera:
    """The face detector's followed face at `fps`, about 1.5 m ahead, a few cm of noise."""

    def __init__(self, node: Node, fps: float) -> None:
        self._pub = node.publisher(keys.FACE, camera="front")
        self.period = 1.0 / fps
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="bench-camera", daemon=True)

    def _run(self) -> None:
        rng = random.Random(3)
        deadline = time.monotonic()
        while not self._stop.is_set():
            point = m.Point(x=1.5 + rng.gauss(0, 0.03), y=rng.gauss(0, 0.02),
                            z=0.1 + rng.gauss(0, 0.02))
            self._pub.put(m.FacePosition(stamp_ns=time.time_ns(), frame_id="front",
                                         point=point, confidence=0.9))
            self.sent += 1
            deadline += self.period
            self._stop.wait(max(0.0, deadline - time.monotonic()))

    def start(self) -> Camera:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)


def _cpu_s(proc: Process) -> float:
    times = psutil.Process(proc.pid).cpu_times()
    return float(times.user + times.system)


def bench_cpu(router: Router, seconds: float, fps: float, folder: Path) -> None:
    people = run_service("people", router.endpoint, "--config",
                         _people_config(folder, engage_dwell_s=0.5))
    probe = Node("bench-people-cpu", connect=[router.endpoint])
    camera: Camera | None = None
    try:
        state = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
        events = Collector[m.PersonEvent](probe, keys.PEOPLE_EVENTS)
        state.wait_for(lambda s: s.people == [], 60, "the first, empty, people/state")
        _wait_subscribed(probe, "people", keys.FACE.key(camera="front"))
        probe.publisher(keys.PRESENCE).put(m.PresenceDetection(
            stamp_ns=time.time_ns(), target_state=m.PresenceTarget.MOVING,
            presence_state=m.PresenceState.IN_RANGE, distance_m=1.5))
        camera = Camera(probe, fps).start()
        events.wait_for(lambda e: e.engagement == "ENGAGED", 30, "the visitor ENGAGED")
        time.sleep(1.0)  # start-up and the engagement settle (not a synchronisation)
        states0, sent0, cpu0 = len(state.messages), camera.sent, _cpu_s(people)
        t0 = time.monotonic()
        time.sleep(seconds)  # the measurement window itself
        dt = time.monotonic() - t0
        cpu = _cpu_s(people) - cpu0
        faces, states = camera.sent - sent0, len(state.messages) - states0
        rss = psutil.Process(people.pid).memory_info().rss / 1e6
    finally:
        if camera is not None:
            camera.stop()
        probe.close()
        people.stop()
    print(f"CPU of people, a visitor, faces at {faces / dt:.1f}/s, people/state at "
          f"{states / dt:.1f}/s: {cpu / dt * 100:.2f} % of one core over {dt:.0f} s "
          f"({cpu / max(faces, 1) * 1e6:.0f} us per face; RSS {rss:.0f} MB)  "
          f"(target: <= 2 %)")


def main() -> int:
    parser = options(__doc__, ("arrival", "cpu"))
    parser.add_argument("--visits", type=int, default=40, help="visits timed (>= 30)")
    parser.add_argument("--cpu-seconds", type=float, default=20.0, help="CPU window")
    parser.add_argument("--fps", type=float, default=30.0, help="faces per second")
    args = parser.parse_args()
    print(host())
    folder = Path(tempfile.mkdtemp(prefix="buddybot-people-bench-"))
    router = Router()
    try:
        if "arrival" not in args.skip:
            bench_arrival(router, args.visits, folder)
        if "cpu" not in args.skip:
            bench_cpu(router, args.cpu_seconds, args.fps, folder)
    finally:
        router.stop()
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
