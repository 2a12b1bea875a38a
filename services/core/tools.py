"""The probing verbs robot people know from `ros2`: echo, hz, pub, call, nodes.

Tools open a plain Zenoh session (no liveliness token: a probe is not a
node of the robot). Keys may omit the `buddybot/<robot>/` prefix and may
contain wildcards; messages are decoded with the catalogue's types.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import statistics
import sys
import threading
import time
from collections import deque
from typing import Any

import msgspec
import zenoh
import zenoh.ext

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.describe import describe
from buddybot.core.errors import ServiceError
from buddybot.core.node import call_service, open_session, zenoh_config
from buddybot.core.rates import span_hz
from buddybot.core.service import ServiceContext


class ToolError(Exception):
    """A user error in a tool's arguments: printed, exit status 2."""


def _session(ctx: ServiceContext) -> zenoh.Session:
    config = zenoh_config(connect=ctx.connect, base_file=ctx.config.zenoh.config_file)
    session = open_session(config, ctx.stop, "router at " + ", ".join(ctx.connect))
    if session is None:
        raise KeyboardInterrupt
    return session


def _is_latched(key: str) -> bool:
    parts = keys.split_absolute(key)
    entry = keys.lookup(parts[1]) if parts else None
    return isinstance(entry, keys.Topic) and entry.latched


def _deadline(seconds: float | None) -> float:
    return time.monotonic() + seconds if seconds else float("inf")


# --- echo ---------------------------------------------------------------------------


def echo(ctx: ServiceContext) -> int:
    """Print every message on KEY, decoded; latched values arrive at once."""
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    count = 0
    done = threading.Event()
    closed = threading.Event()
    lock = threading.Lock()

    def on_sample(sample: zenoh.Sample) -> None:
        nonlocal count
        if sample.kind != zenoh.SampleKind.PUT:
            return
        text = describe(str(sample.key_expr), sample.payload.to_bytes())
        with lock:
            if done.is_set():
                return
            line = f"{sample.key_expr}: {text}" if args.show_key else text
            try:
                print(line, flush=True)
            except (BrokenPipeError, ValueError):  # `| head` closed the pipe: stop quietly
                closed.set()
                done.set()
                return
            count += 1
            if args.count and count >= args.count:
                done.set()

    session = _session(ctx)
    try:
        if _is_latched(key) or "*" in key:
            sub: Any = zenoh.ext.declare_advanced_subscriber(
                session, key, on_sample,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
            )
        else:
            sub = session.declare_subscriber(key, on_sample)
        end = _deadline(args.timeout)
        while not done.is_set() and not ctx.stop.is_set() and time.monotonic() < end:
            done.wait(0.1)
        sub.undeclare()
    finally:
        session.close()
    if closed.is_set():
        with contextlib.suppress(OSError):  # no traceback at exit for the closed stdout
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115
        return 0
    if args.count and count < args.count:
        print(f"buddybot echo: got {count} of {args.count} messages", file=sys.stderr)
        return 1
    return 0


# --- hz -----------------------------------------------------------------------------


def rate_report(stamps: list[float]) -> str | None:
    """ros2-style rate line from arrival times (seconds), or None if < 2."""
    if len(stamps) < 2:
        return None
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    rate = span_hz(stamps)
    std = statistics.pstdev(gaps)
    return (f"average rate: {rate:.3f} Hz\n\tmin: {min(gaps):.4f}s max: {max(gaps):.4f}s "
            f"std dev: {std:.5f}s window: {len(stamps)}")


def hz(ctx: ServiceContext) -> int:
    """Print the publishing rate of KEY every second over a sliding window."""
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    stamps: deque[float] = deque(maxlen=args.window)
    lock = threading.Lock()

    def on_sample(_sample: zenoh.Sample) -> None:
        with lock:
            stamps.append(time.monotonic())

    session = _session(ctx)
    printed = 0
    try:
        sub = session.declare_subscriber(key, on_sample)
        end = _deadline(args.duration)
        while not ctx.stop.wait(1.0) and time.monotonic() < end:
            with lock:
                report = rate_report(list(stamps))
            print(report or "no new messages", flush=True)
            printed += report is not None
        sub.undeclare()
    finally:
        session.close()
    return 0 if printed or not args.duration else 1


# --- pub ----------------------------------------------------------------------------


def parse_message(topic_or_type: type[m.Message], text: str) -> m.Message:
    """Validate user JSON against a message type; fills a missing `stamp_ns`.

    Raises ToolError naming the offending field.
    """
    try:
        raw = msgspec.json.decode(text or "{}")
    except msgspec.DecodeError as exc:
        raise ToolError(f"not valid JSON: {exc}") from None
    if not isinstance(raw, dict):
        raise ToolError(f"expected a JSON object for {topic_or_type.__name__}")
    if "stamp_ns" in topic_or_type.__struct_fields__ and "stamp_ns" not in raw:
        raw["stamp_ns"] = m.now_ns()
    try:
        return msgspec.convert(raw, topic_or_type)
    except msgspec.ValidationError as exc:
        text = str(exc).replace("$.", "").replace("`$`", "message")
        raise ToolError(f"invalid {topic_or_type.__name__}: {text}") from None


def pub(ctx: ServiceContext) -> int:
    """Validate a message against KEY's type, then publish it (once, or at --rate)."""
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    parts = keys.split_absolute(key)
    entry = keys.lookup(parts[1]) if parts else None
    if not isinstance(entry, keys.Topic):
        raise ToolError(f"{args.key}: not a topic of the catalogue (see `buddybot keys`)")
    if "*" in key:
        raise ToolError(f"{args.key}: cannot publish on a wildcard key")
    msg = parse_message(entry.type, args.message)
    session = _session(ctx)
    try:
        publisher = session.declare_publisher(
            key, encoding=zenoh.Encoding(entry.encoding),
            congestion_control=zenoh.CongestionControl.DROP,
        )
        # Give discovery a moment so the first put reaches existing subscribers.
        end = time.monotonic() + args.wait
        while time.monotonic() < end and not publisher.matching_status.matching:
            time.sleep(0.02)
        sent = 0
        while not ctx.stop.is_set():
            if hasattr(msg, "stamp_ns") and args.rate and "stamp_ns" not in args.message:
                msg = msgspec.structs.replace(msg, stamp_ns=m.now_ns())
            publisher.put(entry.codec.encode(msg))
            sent += 1
            if not args.rate or (args.times and sent >= args.times):
                break
            ctx.stop.wait(1.0 / args.rate)
        time.sleep(0.1)  # let the last put leave before the session closes
        publisher.undeclare()
    finally:
        session.close()
    print(f"published {sent} x {type(msg).__name__} on {key}", file=sys.stderr)
    return 0


# --- call ---------------------------------------------------------------------------


def call(ctx: ServiceContext) -> int:
    """Query a service or action goal of the catalogue and print the reply."""
    args = ctx.args
    key = keys.absolute(ctx.robot, args.key)
    parts = keys.split_absolute(key)
    entry = keys.lookup(parts[1]) if parts else None
    if not isinstance(entry, keys.Service):
        raise ToolError(f"{args.key}: not a service of the catalogue (see `buddybot keys`)")
    request = parse_message(entry.request, args.request)
    session = _session(ctx)
    try:
        reply = call_service(session, key, entry, request, args.timeout)
    except ServiceError as exc:
        print(f"buddybot call: {exc}", file=sys.stderr)
        return 1
    finally:
        session.close()
    print(msgspec.json.encode(reply).decode(), flush=True)
    return 0


# --- nodes --------------------------------------------------------------------------


def list_node_instances(
    session: zenoh.Session, robot: str | None, timeout: float = 2.0
) -> dict[str, set[str]]:
    """Live node names (`robot/name` when robot is None) -> their instances (zids),
    from liveliness tokens. More than one instance of a name is a duplicate."""
    pattern = keys.NODES.wildcard()
    key = f"{keys.PREFIX_ROOT}/{robot or '*'}/{pattern}"
    found: dict[str, set[str]] = {}
    for reply in session.liveliness().get(key, timeout=timeout):
        if reply.ok is None:
            continue
        parts = keys.split_absolute(str(reply.ok.key_expr))
        if parts is None:
            continue
        match = keys.NODES.match(parts[1])
        if match:
            name = match["node"] if robot else f"{parts[0]}/{match['node']}"
            found.setdefault(name, set()).add(match["instance"])
    return found


def list_nodes(session: zenoh.Session, robot: str | None, timeout: float = 2.0) -> list[str]:
    """Live node names (`robot/name` when robot is None), from liveliness tokens."""
    return sorted(list_node_instances(session, robot, timeout))


def nodes(ctx: ServiceContext) -> int:
    session = _session(ctx)
    try:
        found = list_node_instances(
            session, None if ctx.args.all_robots else ctx.robot, ctx.args.timeout)
    finally:
        session.close()
    for name in sorted(found):
        instances = sorted(found[name])
        if len(instances) > 1:
            print(f"{name}  DUPLICATE: {len(instances)} instances ({', '.join(instances)})")
        else:
            print(name)
    return 0


def key_list(ctx: ServiceContext) -> int:
    """Print the key catalogue (what `echo`, `pub` and `call` accept)."""
    for row in keys.key_table():
        kind = row["kind"]
        what = row.get("type") or (f"{row.get('request')} -> {row.get('reply')}"
                                   if kind == "service" else "")
        latched = " latched" if row.get("latched") else ""
        print(f"{row['key']:<28} {kind:<10} {what}{latched}")
    return 0
