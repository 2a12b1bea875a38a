"""SDK benchmark: the memory of an idle app; an app's expression to the bus. Prints figures.

    .venv/bin/python benchmarks/sdk.py [--settle-s 3] [--count 100] [--rate 10]

1. Idle app memory: a program (its own process) connects a `Bot` to a real
   router on 127.0.0.1 with a `people` service, subscribes to the people
   events (`bot.on(...)`) and idles. Its VmRSS (/proc/<pid>/status) once
   it settled, and what it imported: the modules loaded, and whether a
   heavy one (numpy, cv2) came in through the runtime.
2. Expression latency: a `controller` process (the lease arbiter, the one
   publisher of `eyes/expression`), a program in this process holding an
   `expression` lease (`bot.lease("expression")`), and a subscriber to
   `eyes/expression` (another node, here). Latency = the arrival of each
   `ScreenExpression` at the subscriber minus the time `bot.eyes.express()`
   was called: bot -> router -> controller (lease check, publish) -> router
   -> subscriber. Expressions alternate so each one is a change, at `--rate`
   per second (under the arbiter's `lease_actions_per_s`, 20). The
   `express()` call's own round trip (it returns on the controller's reply)
   is printed beside it.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import threading
import time

import results
from common import host, options, percentile

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import Bot
from buddybot.tools.testing import Router, retry_until, run_service

IDLE_APP = """
import sys

from buddybot.sdk import Bot

with Bot.connect(connect=[sys.argv[1]], timeout=30) as bot:
    bot.on(("ARRIVED", "ENGAGEMENT_CHANGED", "ZONE_CHANGED", "LEFT"), lambda event: None)
    heavy = sorted(name for name in ("numpy", "cv2", "PIL", "psutil") if name in sys.modules)
    print("ready", len(sys.modules), ",".join(heavy) or "-", flush=True)
    sys.stdin.read()  # idle until the benchmark closes our stdin
"""


def vm_rss_mb(pid: int) -> float:
    """VmRSS of a process, from /proc/<pid>/status."""
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for pid {pid}")


def bench_idle_rss(router: Router, settle_s: float) -> None:
    people = run_service("people", router.endpoint)
    app = subprocess.Popen([sys.executable, "-c", IDLE_APP, router.endpoint],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert app.stdout is not None
        line = app.stdout.readline().split()  # waits for the app (its connect is bounded)
        if not line or line[0] != "ready":
            raise RuntimeError(f"the idle app failed: {line}")
        modules, heavy = int(line[1]), line[2]
        time.sleep(settle_s)  # threads started, first samples in (not a synchronisation)
        rss = vm_rss_mb(app.pid)
    finally:
        if app.stdin is not None:
            app.stdin.close()
        app.wait(timeout=30)
        people.stop()
    print(f"idle app (Bot + bot.on people events), VmRSS after {settle_s:g} s: {rss:.1f} MB; "
          f"{modules} modules imported, heavy ones: {heavy}  (target: <= 45 MB)")


class Screen:
    """A subscriber to `eyes/expression`: when the expression awaited arrived."""

    def __init__(self, node: Node) -> None:
        self._cond = threading.Condition()
        self._awaited: m.ExpressionAction | None = None
        self._arrived_ns: int | None = None
        node.subscribe(keys.EXPRESSION, self._on, history=False)

    def _on(self, msg: m.ScreenExpression, _key: str) -> None:
        now = time.perf_counter_ns()
        with self._cond:
            if msg.action == self._awaited and self._arrived_ns is None:
                self._arrived_ns = now
                self._cond.notify_all()

    def expect(self, action: m.ExpressionAction) -> None:
        with self._cond:
            self._awaited, self._arrived_ns = action, None

    def arrival(self, timeout: float) -> int:
        with self._cond:
            if not self._cond.wait_for(lambda: self._arrived_ns is not None, timeout):
                raise TimeoutError(f"no {self._awaited} on eyes/expression within {timeout} s")
            assert self._arrived_ns is not None
            return self._arrived_ns


EXPRESSIONS = (m.ExpressionAction.ANIMATE_LOVE, m.ExpressionAction.EYE_GRIN,
               m.ExpressionAction.ANIMATE_STAR, m.ExpressionAction.EYE_SAD)


def bench_express(router: Router, count: int, rate: float) -> None:
    arbiter = run_service("eyes", router.endpoint)
    screen_node = Node("bench-screen", connect=[router.endpoint])
    try:
        retry_until(lambda: any(i.node == "eyes" and "leases/acquire" in i.services
                                and "eyes/command" in i.services
                                for i in screen_node.node_infos(1.0)),
                    60, 0.2, "the eyes driver serving leases")
        screen = Screen(screen_node)
        latencies: list[float] = []
        calls: list[float] = []
        with Bot.connect(connect=[router.endpoint], name="bench_app", timeout=10) as bot, \
                bot.lease("expression"):
            for i in range(count):
                action = EXPRESSIONS[i % len(EXPRESSIONS)]
                screen.expect(action)
                t0 = time.perf_counter_ns()
                bot.eyes.express(action)
                returned = time.perf_counter_ns()
                arrived = screen.arrival(10)
                latencies.append((arrived - t0) / 1e6)
                calls.append((returned - t0) / 1e6)
                time.sleep(1.0 / rate)  # the pace (not a synchronisation)
    finally:
        screen_node.close()
        arbiter.stop()
    print(f"bot.eyes.express() called -> ScreenExpression at a subscriber (n={len(latencies)}, "
          f"{rate:g}/s, under a held lease): median {statistics.median(latencies):.2f} ms, "
          f"p90 {percentile(latencies, 0.9):.2f} ms, max {max(latencies):.2f} ms  "
          f"(target: median <= 3 ms)")
    print(f"bot.eyes.express() call itself (returns on the arbiter's reply): median "
          f"{statistics.median(calls):.2f} ms, p90 {percentile(calls, 0.9):.2f} ms, "
          f"max {max(calls):.2f} ms")


def main() -> int:
    parser = options(__doc__, ("rss", "express"))
    parser.add_argument("--settle-s", type=float, default=3.0,
                        help="idle time before the app's RSS is read")
    parser.add_argument("--count", type=int, default=100, help="expressions timed")
    parser.add_argument("--rate", type=float, default=10.0, help="expressions per second")
    args = parser.parse_args()
    print(host())
    router = Router()
    try:
        if "rss" not in args.skip:
            bench_idle_rss(router, args.settle_s)
        if "express" not in args.skip:
            bench_express(router, args.count, args.rate)
    finally:
        router.stop()
    return 0


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
