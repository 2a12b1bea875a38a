"""Benchmark: a lease's grant and an `eyes/command` round trip, through a real router.

Starts `buddybot router` and `buddybot run eyes` (the arbiter) on loopback;
a probe node asks for an `expression` lease, sends five commands with its
handle (one every 60 ms: under the default action rate), releases it, and
does that `--count` times. Prints the median and p90 of the grant (asked ->
granted) and of the command (sent -> the arbiter's reply), the first
20 grants and 100 commands left out (discovery, warm-up).

    .venv/bin/python benchmarks/leases.py [--count N]
"""

from __future__ import annotations

import argparse
import statistics
import time

import results
from common import percentile

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing
from buddybot.runtime.node import Node
from buddybot.tools.testing import Router, retry_until, run_service

COMMANDS_PER_LEASE = 5


def figures(what: str, values: list[float]) -> str:
    return (f"{what}: median {statistics.median(values):.2f} ms, "
            f"p90 {percentile(values, 0.9):.2f} ms, max {max(values):.2f} ms (n={len(values)})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=120)
    args = parser.parse_args()
    router = Router()
    arbiter = run_service("eyes", router.endpoint)
    node = Node("bench-app", connect=[router.endpoint])
    try:
        retry_until(lambda: any(i.node == "eyes" and "leases/acquire" in i.services
                                for i in node.node_infos(1.0)), 60, 0.2, "the arbiter")
        grants: list[float] = []
        commands: list[float] = []
        for _ in range(args.count):
            asked = time.perf_counter()
            reply = leasing.ask(node, m.LeaseRequest(holder=node.name, instance=node.instance,
                                                     resources=["expression"]), timeout=10)
            grants.append((time.perf_counter() - asked) * 1e3)
            if not reply.granted:
                print(f"refused: {reply.message}")
                return 1
            for _ in range(COMMANDS_PER_LEASE):
                sent = time.perf_counter()
                node.call(keys.EYES_COMMAND, m.EyesCommand(
                    lease_id=reply.lease_id, expression=m.ExpressionAction.EYE_GRIN), timeout=10)
                commands.append((time.perf_counter() - sent) * 1e3)
                time.sleep(0.06)  # the pace, under 20 commands/s (not a synchronisation)
            node.call(keys.LEASE_RELEASE, m.LeaseRelease(lease_id=reply.lease_id), timeout=10)
    finally:
        node.close()
        arbiter.stop()
        router.stop()
    print(figures("lease grant (leases/acquire, asked -> granted)", grants[20:]))
    print(figures("eyes/command with the handle (sent -> replied)", commands[100:]))
    return 0


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
