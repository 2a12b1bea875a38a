"""Benchmark: face message -> published eye control, through a real router.

Starts `buddybot router` and `buddybot run controller` on loopback, then a
probe node publishes faces on `camera/front/face` and times each until the
matching `eyes/control` (same `stamp_ns`) comes back. The figure covers
probe -> router -> controller -> router -> probe, i.e. the controller's
work plus two router crossings; a loopback baseline (probe -> router ->
probe on a scratch key) is printed next to it so the controller's own
share can be read off. Also prints the pure per-face cost of the
transform + behaviour step without any I/O, and the behaviour's decision
time per event (a people state with 1, 2 and 5 persons: attention and
motion; a face while two people are there; a tick), in this process.

    .venv/bin/python benchmarks/controller.py [--count N] [--rate HZ]
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
import threading
import time
import timeit

import msgspec
import results
import zenoh
from common import percentile, summary

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.controller.behaviour import Behaviour
from buddybot.controller.settings import ControllerSettings
from buddybot.controller.transform import Gaze, RigidTransform, face_gaze
from buddybot.runtime.node import Node
from buddybot.sdk.persons import Person
from buddybot.tools.testing import Router, retry_until, run_service


class Timer:
    """Send times by stamp_ns and the latencies of the answers that came back."""

    def __init__(self) -> None:
        self.sent: dict[int, int] = {}
        self.latencies_ms: list[float] = []
        self.lock = threading.Lock()

    def arrived(self, stamp: int) -> None:
        now = time.perf_counter_ns()
        with self.lock:
            start = self.sent.pop(stamp, None)
            if start is not None:
                self.latencies_ms.append((now - start) / 1e6)


def run_faces(node: Node, count: int, rate: float) -> list[float]:
    timer = Timer()
    node.subscribe(keys.BEHAVIOUR_GAZE, lambda msg, _k: timer.arrived(msg.stamp_ns))
    pub = node.publisher(keys.FACE, camera="front")
    point = m.Point(x=1.0, y=0.2, z=0.1)

    def send() -> int:
        """One face, stamped now (the controller replaces an implausible stamp by
        its arrival time, and the answer would not be found by it)."""
        stamp = m.now_ns()
        with timer.lock:
            timer.sent[stamp] = time.perf_counter_ns()
        pub.put(m.FacePosition(stamp_ns=stamp, frame_id="front", point=point, confidence=0.9))
        return stamp

    # Wait until the controller answers at all (discovery), then warm up.
    retry_until(lambda: send() and timer.latencies_ms, 30, 0.2, what="controller answering")
    for _ in range(200):
        send()
        time.sleep(1.0 / rate)
    timer.latencies_ms.clear()
    period = 1.0 / rate
    next_t = time.perf_counter()
    last = 0
    for _ in range(count):
        last = send()
        next_t += period
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    # The last face is always answered (nothing supersedes it); earlier ones may be
    # dropped by the controller's latest-value slot when two arrive within one wake-up.
    retry_until(lambda: last not in timer.sent, 10, 0.05, what="answer to the last face")
    return list(timer.latencies_ms)


def run_loopback(endpoint: str, count: int, rate: float) -> list[float]:
    """Baseline: one probe puts on a scratch key and hears it back through the router."""
    timer = Timer()
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("connect/endpoints", f'["{endpoint}"]')
    key = "buddybot/bench/loopback"
    with zenoh.open(config) as a, zenoh.open(config) as b:
        b.declare_subscriber(key, lambda s: timer.arrived(int(s.payload.to_string())))
        pub = a.declare_publisher(key, express=True)

        def send(stamp: int) -> None:
            with timer.lock:
                timer.sent[stamp] = time.perf_counter_ns()
            pub.put(str(stamp))

        retry_until(lambda: send(1) or timer.latencies_ms, 30, 0.2, what="loopback")
        timer.latencies_ms.clear()
        period = 1.0 / rate
        for i in range(count):
            send(1000 + i)
            time.sleep(period)
        retry_until(lambda: len(timer.latencies_ms) >= count * 0.99 or None, 10, 0.1,
                    what="loopback answers")
    return list(timer.latencies_ms)


def pure_cost_us() -> float:
    settings = msgspec.convert({"recover_s": 0.0}, ControllerSettings)
    behaviour = Behaviour(settings, 0.0)
    transform = RigidTransform.from_rpy((0.0, 0.02, 0.1), (0.0, 0.1, 0.0))
    clock = [0.0]

    def step() -> None:
        clock[0] += 0.01
        behaviour.face(clock[0], face_gaze(transform, (1.0, 0.2, 0.1)), 1)

    n = 20000
    return timeit.timeit(step, number=n) / n * 1e6


def decision_costs(n: int = 3000) -> list[str]:
    """Median and p99 of one decision per event kind (us), on a visit in progress."""
    settings = msgspec.convert({"recover_s": 0.0}, ControllerSettings)
    lines = []
    for crowd in (1, 2, 5):
        behaviour = Behaviour(settings, 0.0, random.Random(1))
        costs: dict[str, list[float]] = {"people": [], "face": [], "tick": []}
        t = 0.0
        behaviour.presence(t, True, 1, face=True)
        for i in range(n):
            t += 0.033
            people = [Person(id=k + 1, zone="PERSONAL", engagement="ENGAGED",
                             distance_m=1.0 + 0.2 * k + 0.01 * math.sin(i / 10),
                             seen_by="BOTH" if k == 0 else "RADAR",
                             yaw_rad=0.3 * k - 0.3) for k in range(crowd)]
            gazes = {p.id: Gaze(p.yaw_rad or 0.0, 0.0, 100.0) for p in people}
            start = time.perf_counter_ns()
            behaviour.people(t, people, gazes, 1)
            middle = time.perf_counter_ns()
            behaviour.face(t, Gaze(-0.3, 0.0, 100.0), 1)
            after_face = time.perf_counter_ns()
            behaviour.tick(t)
            end = time.perf_counter_ns()
            costs["people"].append((middle - start) / 1e3)
            costs["face"].append((after_face - middle) / 1e3)
            costs["tick"].append((end - after_face) / 1e3)
        for kind, values in costs.items():
            lines.append(f"decision per {kind} event, {crowd} person(s): median "
                         f"{statistics.median(values):.1f} us, p99 "
                         f"{percentile(values, 0.99):.1f} us")
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--rate", type=float, default=50.0,
                        help="faces per second (a camera gives 10-30)")
    args = parser.parse_args()
    print(f"pure transform + behaviour step per face: {pure_cost_us():.1f} us")
    for line in decision_costs():
        print(line)
    router = Router()
    controller = run_service("controller", router.endpoint)
    try:
        with Node("bench", connect=[router.endpoint]) as node:
            lat = run_faces(node, args.count, args.rate)
        base = run_loopback(router.endpoint, args.count, args.rate)
        print(summary("face -> eye control via router (2 crossings)", lat))
        print(summary("baseline loopback probe -> router -> probe", base))
        print(f"controller share (median difference): "
              f"{statistics.median(lat) - statistics.median(base):.3f} ms")
        print(f"answered {len(lat)}/{args.count} faces (the rest superseded in the "
              f"latest-value slot)")
    finally:
        controller.stop()
        router.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
