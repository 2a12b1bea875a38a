"""`buddybot topics`: the keys alive on the robot, their rates, who publishes and reads them.

Two sources, each reliable for what it says:

* traffic: a raw subscription to `buddybot/<robot>/**` for `--timeout`
  seconds counts the samples of every key (msgs/s = samples / window).
  A key whose publisher is silent in that window (a latched state that
  did not change) shows 0 msgs/s: nothing was sent, which is the truth.
* declarations: every node answers `node_info/<name>` with the keys it
  publishes and subscribes (`Node.declared()`), so publishers and
  subscribers are named by the nodes themselves. A key declared by a
  node but silent is listed too. Tools that are probes (`echo`, `hz`,
  this one) declare nothing and are not named; neither is a non-BuddyBot
  Zenoh client. Zenoh's own matching status is not used: it only tells
  a publisher *whether* someone matches, never who.
"""

from __future__ import annotations

import argparse
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

import msgspec

from buddybot.contract import keyexpr, keys
from buddybot.contract import messages as m
from buddybot.runtime import options, rates
from buddybot.runtime.service import ServiceContext

HELP = "keys seen on the robot with their rates, publishers and subscribers"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    options.add_timeout_argument(parser, 3.0, "listen S seconds: rates are measured over "
                                 "this window", connecting=False)
    options.add_json_argument(parser)


class TopicRow(msgspec.Struct, kw_only=True):
    key: str
    """Relative to `buddybot/<robot>/`."""
    count: int
    rate_hz: float
    publishers: list[str]
    subscribers: list[str]
    type: str = ""


@dataclass
class Traffic:
    """Samples per key (absolute), counted in Zenoh's thread."""

    counts: Counter[str] = field(default_factory=Counter)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_sample(self, key: str, _payload: bytes, _encoding: str) -> None:
        with self.lock:
            self.counts[key] += 1


def table(counts: dict[str, int], window_s: float, infos: list[m.NodeInfo]) -> list[TopicRow]:
    """One row per key seen or declared as published (keys relative)."""
    declared = {k for info in infos for k in info.publishers if "*" not in k}
    rows = []
    for key in sorted(set(counts) | declared):
        entry = keys.lookup(key)
        rows.append(TopicRow(
            key=key, count=counts.get(key, 0),
            rate_hz=round(rates.count_hz(counts.get(key, 0), window_s), 2),
            publishers=sorted({i.node for i in infos
                               if any(keyexpr.intersects(key, k) for k in i.publishers)}),
            subscribers=sorted({i.node for i in infos
                                if any(keyexpr.intersects(key, k) for k in i.subscriptions)}),
            type=entry.type.__name__ if isinstance(entry, keys.Topic) else "",
        ))
    return rows


def main(ctx: ServiceContext) -> int:
    args = ctx.args
    prefix = keys.prefix(ctx.robot)
    traffic = Traffic()
    with ctx.probe() as node:
        start = time.monotonic()
        node.subscribe_raw(f"{prefix}/**", traffic.on_sample)
        infos = node.node_infos(min(args.timeout, 5.0))
        ctx.stop.wait(max(0.0, args.timeout - (time.monotonic() - start)))
        window = time.monotonic() - start
        with traffic.lock:
            counts = {node.relative(k): n for k, n in traffic.counts.items()}
    rows = table(counts, window, infos)
    if args.json:
        print(msgspec.json.encode(rows).decode())
        return 0
    width = max([len(r.key) for r in rows] + [3])
    print(f"{'KEY'.ljust(width)}  {'MSGS/S':>8}  PUBLISHERS -> SUBSCRIBERS")
    for r in rows:
        pubs = ", ".join(r.publishers) or "?"
        subs = ", ".join(r.subscribers) or "-"
        print(f"{r.key.ljust(width)}  {r.rate_hz:8.2f}  {pubs} -> {subs}")
    return 0
