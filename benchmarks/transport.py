"""Transport benchmark: bare zenoh-python against the BuddyBot node runtime.

Through a real `buddybot router` on loopback, in the same run:

* round trip (median, p99) of a small control message and of a 640x480
  BGR image, ping here -> echo process -> pong here;
* throughput (messages/s received) of the same payloads, one publisher
  session and one subscriber session in this process, via the router.

"bare" puts and receives raw bytes with zenoh-python; "node" goes through
`Node.publisher()` / `Node.subscribe()` with msgspec encoding and
validation. The ratio node/bare is what the runtime adds (target <= 1.3).

    .venv/bin/python benchmarks/transport.py [--rounds 2000] [--seconds 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import results
import zenoh
from common import ROUTES, make_message, percentile, reply_for

from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, Router, retry_until

ROBOT = "bench"

# --- echo process -------------------------------------------------------------------


def echo_main(endpoint: str, mode: str, kind: str) -> None:
    """Answer every ping with a pong, bare or through the runtime."""
    ping, pong, ping_p, pong_p = ROUTES[kind]
    stop = threading.Event()
    node = Node(f"echo-{mode}-{kind}", robot=f"{ROBOT}-{mode}", connect=[endpoint],
                stop_event=stop)
    if mode == "bare":
        # Bare zenoh-python on purpose (the node's private session): the baseline.
        out = node._session.declare_publisher(node.key(pong, **pong_p))
        node._own(out)

        def on_sample(sample: zenoh.Sample) -> None:
            out.put(sample.payload)

        node._own(node._session.declare_subscriber(node.key(ping, **ping_p), on_sample))
    else:
        pub = node.publisher(pong, **pong_p)
        node.subscribe(ping, lambda msg, _k: pub.put(reply_for(msg)), **ping_p)
    print("READY", flush=True)
    try:
        node.spin()  # until SIGTERM from the parent
    finally:
        node.close()


# --- measurements -------------------------------------------------------------------


class Pinger:
    """One side of a ping-pong path (bare or node) to its echo process."""

    def __init__(self, endpoint: str, mode: str, kind: str) -> None:
        ping, pong, ping_p, pong_p = ROUTES[kind]
        self.echo = Process([sys.executable, __file__, "--echo", endpoint, mode, kind],
                            f"echo-{mode}")
        self.node = node = Node(f"ping-{mode}-{kind}", robot=f"{ROBOT}-{mode}",
                                connect=[endpoint])
        self.got = got = threading.Event()
        self.samples: list[float] = []
        if mode == "bare":
            out = node._session.declare_publisher(node.key(ping, **ping_p))
            node._own(out)
            payload = ping.codec.encode(make_message(kind, 1))
            self.send = lambda: out.put(payload)

            def on_sample(_sample: zenoh.Sample) -> None:
                got.set()

            node._own(node._session.declare_subscriber(node.key(pong, **pong_p), on_sample))
        else:
            pub = node.publisher(ping, **ping_p)
            message = make_message(kind, 1)
            self.send = lambda: pub.put(message)
            node.subscribe(pong, lambda _msg, _k: got.set(), **pong_p)

    def ready(self) -> None:
        self.echo.wait_for_output("READY", 30)

        def warm() -> bool:
            self.got.clear()
            self.send()
            return self.got.wait(0.2)

        retry_until(warm, 20, 0.0, "echo path")

    def once(self) -> None:
        self.got.clear()
        start = time.perf_counter()
        self.send()
        if self.got.wait(2.0):  # a lost sample (DROP under load) is not a round trip
            self.samples.append((time.perf_counter() - start) * 1e3)

    def close(self) -> None:
        self.node.close()
        self.echo.stop()


def round_trips(endpoint: str, kind: str, rounds: int) -> dict[str, list[float]]:
    """Bare and node round trips, interleaved so machine noise hits both alike."""
    pingers = {mode: Pinger(endpoint, mode, kind) for mode in ("bare", "node")}
    try:
        for pinger in pingers.values():
            pinger.ready()
        for _ in range(rounds):
            for pinger in pingers.values():
                pinger.once()
        return {mode: p.samples for mode, p in pingers.items()}
    finally:
        for pinger in pingers.values():
            pinger.close()


def throughput(endpoint: str, mode: str, kind: str, seconds: float) -> float:
    ping, _pong, ping_p, _ = ROUTES[kind]
    sender = Node(f"tx-{mode}", robot=ROBOT, connect=[endpoint])
    receiver = Node(f"rx-{mode}", robot=ROBOT, connect=[endpoint])
    count = [0]
    try:
        send: Callable[[], None]
        if mode == "bare":
            def on_sample(_sample: zenoh.Sample) -> None:
                count[0] += 1

            receiver._own(receiver._session.declare_subscriber(
                receiver.key(ping, **ping_p), on_sample))
            out = sender._session.declare_publisher(
                sender.key(ping, **ping_p), congestion_control=zenoh.CongestionControl.BLOCK)
            sender._own(out)
            payload = ping.codec.encode(make_message(kind, 1))

            def send() -> None:
                out.put(payload)
        else:
            def on_msg(_msg: Any, _k: str) -> None:
                count[0] += 1

            receiver.subscribe(ping, on_msg, **ping_p)
            pub = sender.publisher(ping, **ping_p)
            message = make_message(kind, 1)

            def send() -> None:
                pub.put(message)

        retry_until(lambda: send() or count[0], 20, 0.05, "first delivery")
        time.sleep(0.2)
        start_count, start = count[0], time.perf_counter()
        while time.perf_counter() - start < seconds:
            send()
        time.sleep(0.3)  # let the tail arrive
        return (count[0] - start_count) / seconds
    finally:
        receiver.close()
        sender.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2000)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    router = Router()
    results: dict[tuple[str, str], dict[str, float]] = {}
    try:
        for kind in ("small", "image"):
            rounds = args.rounds if kind == "small" else max(200, args.rounds // 4)
            rtts = round_trips(router.endpoint, kind, rounds)
            for mode in ("bare", "node"):
                rtt = rtts[mode]
                rate = throughput(router.endpoint, mode, kind, args.seconds)
                results[(kind, mode)] = {
                    "median": statistics.median(rtt), "p99": percentile(rtt, 0.99),
                    "n": len(rtt), "rate": rate,
                }
    finally:
        router.stop()
    print(f"{'payload':<8}{'mode':<6}{'rtt median ms':>15}{'rtt p99 ms':>12}"
          f"{'round trips':>13}{'msgs/s':>12}")
    for (kind, mode), r in results.items():
        print(f"{kind:<8}{mode:<6}{r['median']:>15.3f}{r['p99']:>12.3f}{r['n']:>13.0f}"
              f"{r['rate']:>12.0f}")
    for kind in ("small", "image"):
        bare, node = results[(kind, "bare")], results[(kind, "node")]
        print(f"{kind}: node/bare round trip median x{node['median'] / bare['median']:.2f}, "
              f"p99 x{node['p99'] / bare['p99']:.2f}, "
              f"throughput x{node['rate'] / bare['rate']:.2f}")


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--echo":
        echo_main(*sys.argv[2:5])
    else:
        sys.exit(results.run(__file__, main))
