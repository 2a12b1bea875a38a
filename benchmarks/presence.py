"""Benchmark: radar presence -> the eyes waking, through a real router.

Starts `buddybot router`, `buddybot run people`, `buddybot run
controller` and `buddybot run eyes` on loopback (the controller reads the
person from `people/state` and wishes its expression, which the eyes
driver's arbiter shows, so an arrival crosses radar/presence -> people ->
controller -> eyes -> eyes/expression), then a probe node publishes IN_RANGE on
`radar/presence` and times it until `eyes/expression` comes back awake
(EYE_ALERT: an LD2410 gives no direction, so the face reacts; EYE_AWAKE
with `--calm`, the alert off); OUT_OF_RANGE and EYE_SLEEP in between reset
the robot. The holds are 0 (the people service's `absence_hold_s`, the
controller's `farewell_delay_s`, `alone_s` and `sleepy_s`) so the cycle is quick; entering
needs no hold, so the figure is the pipeline's own latency: the people
service's step, the controller's decision thread, the arbiter and five
router crossings. A loopback baseline (probe -> router -> probe) is
printed next to it.

    .venv/bin/python benchmarks/presence.py [--count N] [--calm]
"""

from __future__ import annotations

import argparse
import threading
import time

import results
from common import services_up, summary

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, retry_until

CONFIG = """
[people]
absence_hold_s = 0.0
[controller]
farewell_delay_s = 0.0
alone_s = 0.0
sleepy_s = 0.0
recover_s = 0.2
"""

X = m.ExpressionAction


def presence(in_range: bool) -> m.PresenceDetection:
    state = m.PresenceState.IN_RANGE if in_range else m.PresenceState.OUT_OF_RANGE
    return m.PresenceDetection(stamp_ns=m.now_ns(), target_state=m.PresenceTarget.STANDING,
                               presence_state=state, distance_m=1.2)


def run_visits(node: Node, count: int, awake: X = X.EYE_ALERT) -> list[float]:
    """`count` arrivals: each one's time from the put to `awake` arriving here."""
    shown: list[X] = []
    arrived = threading.Condition()

    def on_expression(msg: m.ScreenExpression, _key: str) -> None:
        with arrived:
            shown.append(msg.action)
            arrived.notify_all()

    def wait(action: X, timeout: float = 10.0) -> None:
        with arrived:
            if not arrived.wait_for(lambda: shown and shown[-1] == action, timeout):
                raise TimeoutError(f"no {action.name} within {timeout} s: {shown[-5:]}")

    node.subscribe(keys.EXPRESSION, on_expression)
    pub = node.publisher(keys.PRESENCE)
    wait(X.EYE_SLEEP, 30.0)
    latencies: list[float] = []
    for i in range(count + 5):  # the first five warm up
        start = time.perf_counter_ns()
        pub.put(presence(True))
        wait(awake)
        if i >= 5:
            latencies.append((time.perf_counter_ns() - start) / 1e6)
        pub.put(presence(False))
        wait(X.EYE_SLEEP)
    return latencies


def run_loopback(sender: Node, receiver: Node, count: int) -> list[float]:
    """Baseline: one node's put heard by another through the router."""
    got = threading.Event()
    receiver.subscribe(keys.EYE_CONTROL, lambda _msg, _key: got.set(), history=False)
    pub = sender.publisher(keys.EYE_CONTROL)

    def msg() -> m.EyeControl:
        return m.EyeControl(stamp_ns=m.now_ns(), yaw=0.0, pitch=0.0, target_distance_cm=100.0)

    retry_until(lambda: pub.put(msg()) or got.wait(0.2), 30, 0.0, what="loopback")
    latencies: list[float] = []
    for _ in range(count):
        got.clear()
        start = time.perf_counter_ns()
        pub.put(msg())
        if not got.wait(5.0):
            raise TimeoutError("loopback sample lost")
        latencies.append((time.perf_counter_ns() - start) / 1e6)
    return latencies


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=50)
    parser.add_argument("--calm", action="store_true",
                        help="no alert face: time the arrival to EYE_AWAKE")
    args = parser.parse_args()
    config = CONFIG + ("alert_s = 0.0\n" if args.calm else "")
    awake = X.EYE_AWAKE if args.calm else X.EYE_ALERT
    with services_up(("people", "controller", "eyes"), config,
                     "buddybot-bench-presence-") as endpoint:
        with Node("bench", connect=[endpoint]) as node:
            Collector(node, keys.PEOPLE_STATE).wait_for(timeout=30, what="people up")
            lat = run_visits(node, args.count, awake)
        with (Node("bench-a", connect=[endpoint]) as a,
              Node("bench-b", connect=[endpoint]) as b):
            base = run_loopback(a, b, args.count)
    print(summary(f"radar/presence -> people -> controller -> eyes -> {awake.name}", lat))
    print(summary("loopback probe -> router -> probe", base))
    return 0


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
