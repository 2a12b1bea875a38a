"""The node runtime: one Zenoh session per process, typed pub/sub, queryables.

Everything a service needs from Zenoh lives here, written once:

* the session is a *client* of the router endpoints, with multicast
  scouting off, and it waits for a router that is not up yet (services
  start in any order) while staying interruptible by Ctrl-C;
* every key is the catalogue's pattern under `buddybot/<robot>/`;
* a liveliness token `nodes/<name>/<zid>` says the node is alive (the zid
  names the process, so a second instance of a name is seen and, for
  services, refused), and `diagnostics/<name>` says how it is doing;
* nothing uses congestion control BLOCK (one stalled reader would stall
  the router): state keys are latched and recovered instead, and a
  stalled link is closed after 100 ms of blocking;
* no sample can freeze or bloat a handler: oversized payloads are dropped
  unread, values are range-checked at decode, and a `stamp_ns` outside
  the plausible window is replaced by the arrival time (counted);
* latched topics use zenoh.ext advanced publishers (a one-sample cache)
  and advanced subscribers (history of late publishers), so a process
  that starts late or restarts gets the current value at once;
* typed subscribers decode and validate every sample; a malformed one is
  dropped, counted and logged at most once per burst, never fatal;
* slow handlers run on a worker fed by a latest-value slot or a bounded
  queue, never in Zenoh's callback thread (a stuck callback starves every
  other key of the session, DESIGN.md section 6).
"""

from __future__ import annotations

import collections
import json
import logging
import os
import signal
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any, Generic, Literal, TypeVar

import msgspec
import zenoh
import zenoh.ext

from buddybot.core import keys, limits
from buddybot.core import messages as m
from buddybot.core.errors import ConfigError, DuplicateNodeError, ServiceError

log = logging.getLogger("buddybot.node")

T = TypeVar("T", bound=m.Message)
Delivery = Literal["inline", "latest", "queue"]

_CONGESTION = {"drop": zenoh.CongestionControl.DROP}
_PRIORITY = {
    "real_time": zenoh.Priority.REAL_TIME,
    "interactive_high": zenoh.Priority.INTERACTIVE_HIGH,
    "data": zenoh.Priority.DATA,
    "background": zenoh.Priority.BACKGROUND,
}


# --- session configuration ------------------------------------------------------

WAIT_BEFORE_CLOSE_US = 100_000
"""Zenoh's `wait_before_close` (microseconds) for router and clients."""
MAX_MESSAGE_BYTES = keys.IMAGE_MESSAGE_BYTES
"""Zenoh's `max_message_size`: nothing larger than the largest image we accept."""


def zenoh_config(
    *,
    mode: Literal["client", "peer", "router"] = "client",
    connect: list[str] | tuple[str, ...] = (),
    listen: list[str] | tuple[str, ...] = (),
    base_file: str | None = None,
) -> zenoh.Config:
    """A Zenoh config with BuddyBot's rules: explicit endpoints, no multicast
    scouting, clients that wait for their router and reconnect quickly."""
    try:
        config = zenoh.Config.from_file(base_file) if base_file else zenoh.Config()
    except zenoh.ZError as exc:  # exit status 2 (systemd units do not restart on it)
        raise ConfigError(f"{base_file}: not a valid Zenoh config: {exc}") from None
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    # A link that stays blocked this long is closed instead of holding back
    # every other stream behind one stalled reader (5 s by default; measured:
    # only this removed the radar gaps when one client was SIGSTOPped).
    config.insert_json5(
        "transport/link/tx/queue/congestion_control/block/wait_before_close",
        str(WAIT_BEFORE_CLOSE_US),
    )
    config.insert_json5("transport/link/rx/max_message_size", str(MAX_MESSAGE_BYTES))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if mode != "router":
        # Wait for the router forever (services start in any order) and retry
        # fast, so a router restart costs ~0.2 s instead of ~4 s.
        config.insert_json5("connect/timeout_ms", "-1")
        config.insert_json5("connect/retry", '{"period_init_ms": 100, "period_max_ms": 500}')
    return config


def open_session(
    config: zenoh.Config, stop: threading.Event, what: str = "router"
) -> zenoh.Session | None:
    """Open a session in a helper thread so the caller stays responsive to a
    stop request while Zenoh waits for the router. None when stopped first."""
    result: dict[str, Any] = {}
    done = threading.Event()

    def opener() -> None:
        try:
            result["session"] = zenoh.open(config)
        except Exception as exc:  # zenoh raises ZError
            result["error"] = exc
        done.set()

    threading.Thread(target=opener, name="zenoh-open", daemon=True).start()
    waited = 0.0
    while not done.wait(0.1):
        if stop.is_set():
            return None
        waited += 0.1
        if abs(waited - 2.0) < 0.05 or (waited > 2 and int(waited * 10) % 100 == 0):
            log.warning("waiting for the Zenoh %s (%.0f s so far)...", what, waited)
    if "error" in result:
        raise ConnectionError(f"cannot open Zenoh session: {result['error']}")
    return result["session"]


# --- diagnostics and rate-limited warnings -----------------------------------------


class RateLimitedLog:
    """Logs the first event of a burst, then at most one summary per period."""

    def __init__(self, logger: logging.Logger, period_s: float = 5.0) -> None:
        self._logger = logger
        self._period = period_s
        self._last: dict[str, float] = {}
        self._suppressed: collections.Counter[str] = collections.Counter()
        self._lock = threading.Lock()

    def warning(self, topic: str, text: str, *args: Any) -> None:
        now = time.monotonic()
        with self._lock:
            last = self._last.get(topic)
            if last is not None and now - last < self._period:
                self._suppressed[topic] += 1
                return
            suppressed = self._suppressed.pop(topic, 0)
            self._last[topic] = now
        suffix = f" (+{suppressed} more since last report)" if suppressed else ""
        self._logger.warning(text + suffix, *args)


class Diagnostics:
    """The node's health, published on `diagnostics/<node>` periodically and on change.

    Services set `level`/`message` with `set()` and keep counters in
    `values` (plain numbers and strings), e.g. frames, reconnects.
    """

    def __init__(self, node: Node, period_s: float) -> None:
        self._node = node
        self._period = period_s
        self._lock = threading.Lock()
        self.level: m.DiagnosticLevel = "OK"
        self.message = "running"
        self.values: dict[str, m.DiagnosticValue] = {}
        self._pub = node.publisher(keys.DIAGNOSTICS, node=node.name)

    def set(self, level: m.DiagnosticLevel, message: str) -> None:
        """Change the status; publishes at once when it differs."""
        message = limits.clip(message)
        with self._lock:
            changed = (level, message) != (self.level, self.message)
            self.level, self.message = level, message
        if changed:
            (log.info if level == "OK" else log.warning)("status %s: %s", level, message)
            self.publish()

    def increment(self, name: str, by: int = 1) -> None:
        with self._lock:
            self.values[name] = int(self.values.get(name, 0)) + by

    def publish(self) -> None:
        # Samples a worker dropped for newer ones ("latest" delivery: expected) or
        # because its queue was full (a handler slower than its input).
        dropped = {f"dropped {w.label}": w.dropped for w in self._node._workers if w.dropped}
        with self._lock:
            status = m.DiagnosticStatus(
                stamp_ns=m.now_ns(), node=self._node.name, level=self.level,
                message=self.message, values={**self.values, **dropped},
            )
        self._pub.put(status)

    def run(self, stop: threading.Event) -> None:
        while not stop.wait(self._period):
            try:
                self.publish()
            except Exception as exc:  # a closed session during shutdown
                log.debug("diagnostics publish failed: %s", exc)


# --- typed publishers ----------------------------------------------------------------


HEARTBEAT_S = 0.5
"""Period of a latched publisher's heartbeat after it published (miss detection)."""


class Publisher(Generic[T]):
    """Puts messages of one catalogue topic on one concrete key."""

    def __init__(self, node: Node, topic: keys.Topic, key: str) -> None:
        self.topic = topic
        self.key = key
        self._encoding = zenoh.Encoding(topic.encoding)
        qos = topic.qos
        options: dict[str, Any] = {
            "encoding": self._encoding,
            "congestion_control": _CONGESTION[qos.congestion],
            "priority": _PRIORITY[qos.priority],
            "express": qos.express,
        }
        self._plain: zenoh.Publisher | None = None
        if topic.latched:
            self._z: Any = zenoh.ext.declare_advanced_publisher(
                node.session, key,
                cache=zenoh.ext.CacheConfig(max_samples=topic.history),
                publisher_detection=True,
                # A sample dropped under congestion is noticed by the next
                # heartbeat and fetched from the cache (state keys use DROP).
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=HEARTBEAT_S
                ),
                **options,
            )
        else:
            self._plain = node.session.declare_publisher(key, **options)
            self._z = self._plain
        node._declared.append(self._z)
        self._encode = topic.codec.encode
        self._put = self._z.put

    def put(self, msg: T) -> None:
        """Encode and put (the encoding was set once, at declaration)."""
        self._put(self._encode(msg))

    def put_bytes(self, payload: bytes) -> None:
        """Put an already encoded payload (for tools and tests)."""
        self._put(payload)

    def has_subscribers(self) -> bool:
        """Whether anyone listens (a latched publisher always answers True)."""
        if self._plain is None:
            return True
        return bool(self._plain.matching_status.matching)


# --- delivery workers ----------------------------------------------------------------


class _Worker:
    """Runs a handler on its own thread, fed by a latest slot or a bounded FIFO."""

    def __init__(self, name: str, handler: Callable[..., None], latest: bool, maxlen: int,
                 on_error: Callable[[BaseException], None], label: str = "") -> None:
        self.label = label or name
        self._handler = handler
        self._on_error = on_error
        self._items: collections.deque[tuple[Any, ...]] = collections.deque(
            maxlen=1 if latest else maxlen
        )
        self._cond = threading.Condition()
        self._closed = False
        self.dropped = 0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, *item: Any) -> None:
        """Queue an item; when full the oldest is dropped (counted)."""
        with self._cond:
            if len(self._items) == self._items.maxlen:
                self.dropped += 1
            self._items.append(item)
            self._cond.notify()

    def offer(self, *item: Any) -> bool:
        """Queue an item unless full: False means the caller must refuse it
        (queries: a dropped query would leave its caller with no answer)."""
        with self._cond:
            if len(self._items) == self._items.maxlen:
                self.dropped += 1
                return False
            self._items.append(item)
            self._cond.notify()
            return True

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._items and not self._closed:
                    self._cond.wait()
                if self._closed and not self._items:
                    return
                item = self._items.popleft()
            try:
                self._handler(*item)
            except Exception as exc:
                self._on_error(exc)

    def close(self, timeout: float = 2.0) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)


# --- the node ----------------------------------------------------------------------


class Node:
    """One service process's connection to the robot.

    Use as a context manager, or call `close()`; `spin()` blocks until
    SIGINT/SIGTERM (or `stop()`).
    """

    def __init__(
        self,
        name: str,
        *,
        robot: str = keys.DEFAULT_ROBOT,
        connect: list[str] | tuple[str, ...] = ("tcp/127.0.0.1:7447",),
        zenoh_config_file: str | None = None,
        diagnostics_period_s: float = 2.0,
        stop_event: threading.Event | None = None,
        session: zenoh.Session | None = None,
        unique: bool = False,
        stamp_window_s: tuple[float, float] = (limits.STAMP_PAST_S, limits.STAMP_FUTURE_S),
    ) -> None:
        """`unique`: refuse to start (DuplicateNodeError) when another process
        already runs a node of this name on this robot (services set it; tools
        and tests that open several probes do not). `stamp_window_s`: how far
        (past, future) a received `stamp_ns` may lie from its arrival time."""
        self.name = name
        self.robot = robot
        self.prefix = keys.prefix(robot)
        self.log = logging.getLogger(f"buddybot.{name}")
        self.stop_event = stop_event or threading.Event()
        self._declared: list[Any] = []
        self._workers: list[_Worker] = []
        self._threads: list[threading.Thread] = []
        self._closed = False
        self._warn = RateLimitedLog(self.log)
        self._stamp_window = stamp_window_s
        if session is None:
            config = zenoh_config(connect=connect, base_file=zenoh_config_file)
            opened = open_session(config, self.stop_event, "router at " + ", ".join(connect))
            if opened is None:
                raise KeyboardInterrupt("stopped while waiting for the router")
            self._owns_session = True
            session = opened
        else:
            self._owns_session = False
        self.session: zenoh.Session = session
        self.instance = str(session.info.zid())
        """This process's identity on the bus (its Zenoh session id)."""
        if unique:
            self._refuse_duplicate()
        self.diagnostics = Diagnostics(self, diagnostics_period_s)
        self._token = self.session.liveliness().declare_token(
            self.key(keys.NODES, node=name, instance=self.instance))
        self.watch_node(name, self._on_own_instances)
        self.every(diagnostics_period_s, self.diagnostics.publish, name="diagnostics")
        self.log.info("node %s up (robot %s, instance %s)", name, robot, self.instance)

    # -- identity --

    def _refuse_duplicate(self) -> None:
        others = live_instances(self.session, self.key(keys.NODES, node=self.name))
        others.discard(self.instance)
        if others:
            if self._owns_session:
                self.session.close()
            raise DuplicateNodeError(
                f"another {self.name} is already running on robot {self.robot} "
                f"(instance {', '.join(sorted(others))}); stop it first, or set "
                "[robot] allow_duplicate_nodes = true to run several on purpose"
            )

    def _on_own_instances(self, instances: frozenset[str]) -> None:
        others = sorted(instances - {self.instance})
        self.diagnostics.values["instances"] = len(instances)
        if others:
            self.diagnostics.set("WARN", f"another {self.name} is running: {', '.join(others)}")
        elif self.diagnostics.message.startswith(f"another {self.name} is running"):
            self.diagnostics.set("OK", "running")

    def watch_node(
        self, name: str, on_change: Callable[[frozenset[str]], None]
    ) -> None:
        """Call `on_change(instances)` with the set of live instances (zids) of
        node `name` now and whenever it changes: one source of truth for "is X
        running", from liveliness tokens only (runs in Zenoh's thread: be quick)."""
        alive: set[str] = set()
        lock = threading.Lock()
        put = zenoh.SampleKind.PUT

        def on_token(sample: zenoh.Sample) -> None:
            found = keys.NODES.match(self.relative(str(sample.key_expr)))
            if found is None:
                return
            with lock:
                if sample.kind == put:
                    alive.add(found["instance"])
                else:
                    alive.discard(found["instance"])
                current = frozenset(alive)
            try:
                on_change(current)
            except Exception as exc:
                self._warn.warning(f"watch:{name}", "node watcher for %s failed: %r", name, exc)

        sub = self.session.liveliness().declare_subscriber(
            self.key(keys.NODES, node=name), on_token, history=True)
        self._declared.append(sub)

    # -- keys --

    def key(self, entry: keys._Entry, /, **params: str) -> str:
        """Absolute key of a catalogue entry; a missing parameter means `*`."""
        filled = {p: params.get(p, "*") for p in entry.params}
        rel = entry.pattern.format(**filled)
        for name, value in params.items():
            if value != "*" and not keys.valid_robot_id(str(value)):
                raise ValueError(f"{entry.pattern}: invalid {name} {value!r}")
        return f"{self.prefix}/{rel}"

    def relative(self, key: str) -> str:
        key = str(key)
        return key[len(self.prefix) + 1:] if key.startswith(self.prefix + "/") else key

    # -- publish / subscribe --

    def publisher(self, topic: keys.Topic, /, **params: str) -> Publisher[Any]:
        key = self.key(topic, **params)
        if "*" in key:
            raise ValueError(f"cannot publish on a wildcard key {key}")
        return Publisher(self, topic, key)

    def subscribe(
        self,
        topic: keys.Topic,
        callback: Callable[[Any, str], None],
        *,
        delivery: Delivery = "inline",
        queue_size: int = 64,
        history: bool | None = None,
        **params: str,
    ) -> None:
        """Call `callback(message, relative_key)` for each valid sample.

        `delivery`: "inline" runs the callback in Zenoh's thread (only for
        fast handlers), "latest" on a worker that only ever sees the newest
        sample, "queue" on a worker with a bounded FIFO (oldest dropped).
        `history` (default: the topic is latched) fetches latched values.
        """
        key = self.key(topic, **params)
        decode = topic.codec.decode
        msg_type = topic.type
        relative_keys: dict[str, str] = {}  # key text -> relative key, computed once

        def rel(key_expr: zenoh.KeyExpr) -> str:
            text = str(key_expr)
            found = relative_keys.get(text)
            if found is None:
                found = relative_keys[text] = self.relative(text)
            return found

        def on_error(exc: BaseException) -> None:
            self.diagnostics.increment("callback_errors")
            self._warn.warning(f"cb:{key}", "handler for %s failed: %r", key, exc)

        inline = delivery == "inline"
        sink: Callable[..., None] = callback
        if not inline:
            worker = _Worker(f"{self.name}:{topic.pattern}", callback, delivery == "latest",
                             queue_size, on_error, label=topic.pattern)
            self._workers.append(worker)
            sink = worker.submit
        put_kind = zenoh.SampleKind.PUT
        bad = (msgspec.DecodeError, msgspec.ValidationError)
        max_bytes = topic.max_bytes
        stamped = "stamp_ns" in msg_type.__struct_fields__
        # A latched value is old by design (it was published when it changed):
        # only its future bound is checked.
        future_ns = int(self._stamp_window[1] * 1e9)
        past_ns = None if topic.latched else int(self._stamp_window[0] * 1e9)

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != put_kind:
                return
            payload = sample.payload
            if len(payload) > max_bytes:
                self.diagnostics.increment("oversized")
                self._warn.warning(
                    f"big:{key}", "dropped a %d-byte sample on %s (limit %d)",
                    len(payload), limits.clip(str(sample.key_expr)), max_bytes,
                )
                return
            try:
                msg = decode(payload.to_bytes(), msg_type)
            except bad as exc:
                self.diagnostics.increment("malformed")
                self._warn.warning(
                    f"bad:{key}", "dropped malformed %s on %s: %s",
                    msg_type.__name__, limits.clip(str(sample.key_expr)), limits.clip(exc),
                )
                return
            if stamped:
                now = time.time_ns()
                stamp = msg.stamp_ns
                if stamp > now + future_ns or (past_ns is not None and stamp < now - past_ns):
                    # Never let one wrong clock hold back every later sample.
                    msg.stamp_ns = now
                    self.diagnostics.increment("stamps replaced")
                    self._warn.warning(
                        f"stamp:{key}", "replaced implausible stamp_ns %d on %s "
                        "(%.1f s from arrival) by the arrival time",
                        stamp, limits.clip(str(sample.key_expr)), (stamp - now) / 1e9,
                    )
            try:
                sink(msg, rel(sample.key_expr))
            except Exception as exc:  # only inline handlers raise here
                on_error(exc)

        use_history = topic.latched if history is None else history
        if use_history:
            sub: Any = zenoh.ext.declare_advanced_subscriber(
                self.session, key, on_sample,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
                subscriber_detection=True,
            )
        else:
            sub = self.session.declare_subscriber(key, on_sample)
        self._declared.append(sub)

    # -- services --

    def serve(
        self,
        service: keys.Service,
        handler: Callable[[Any], m.Message],
        *,
        queue_size: int = 16,
        **params: str,
    ) -> None:
        """Answer queries on a catalogue service with `handler(request) -> reply`.

        Handlers run on a worker thread (they may do I/O); a malformed request
        or a failing handler gets an error reply naming the problem.
        """
        key = self.key(service, **params)
        codec = service.codec
        reply_encoding = zenoh.Encoding(codec.encoding(service.reply))

        def answer(query: zenoh.Query) -> None:
            # Replies leave only when the query is finalized: drop it explicitly
            # (zenoh-python #459), also on the error paths.
            with query:
                _answer(query)

        def _answer(query: zenoh.Query) -> None:
            payload = query.payload
            raw = payload.to_bytes() if payload is not None else b"{}"
            try:
                request = codec.decode(raw or b"{}", service.request)
            except (msgspec.DecodeError, msgspec.ValidationError) as exc:
                self.diagnostics.increment("malformed")
                text = limits.clip(exc)
                self._warn.warning(f"bad:{key}", "refused malformed request on %s: %s", key, text)
                query.reply_err(_error_payload(f"bad {service.request.__name__}: {text}"))
                return
            try:
                reply = handler(request)
            except Exception as exc:
                self.log.exception("handler for %s failed", key)
                query.reply_err(_error_payload(f"{type(exc).__name__}: {limits.clip(exc)}"))
                return
            query.reply(key, codec.encode(reply), encoding=reply_encoding)

        def on_error(exc: BaseException) -> None:
            self.log.error("query handling on %s failed: %r", key, exc)

        worker = _Worker(f"{self.name}:{service.pattern}", answer, False, queue_size, on_error,
                         label=service.pattern)
        self._workers.append(worker)

        def on_query(query: zenoh.Query) -> None:
            # Every query gets an answer: too large or too many at once are
            # refused here at once (Zenoh's thread; replying is quick), never
            # silently dropped.
            payload = query.payload
            if payload is not None and len(payload) > service.max_bytes:
                self.diagnostics.increment("oversized")
                with query:
                    query.reply_err(_error_payload(
                        f"request too large: {len(payload)} bytes (limit {service.max_bytes})"))
                return
            if not worker.offer(query):
                self.diagnostics.increment("busy")
                self._warn.warning(f"busy:{key}", "refused a request on %s: busy", key)
                with query:
                    query.reply_err(_error_payload(
                        f"busy: {queue_size} requests already waiting on {service.pattern}"))

        self._declared.append(self.session.declare_queryable(key, on_query))

    def call(
        self, service: keys.Service, request: m.Message, *, timeout: float = 5.0, **params: str
    ) -> Any:
        """Query a service; returns the decoded reply or raises ServiceError."""
        return call_service(self.session, self.key(service, **params), service, request, timeout)

    # -- timers, lifetime --

    def every(self, period_s: float, fn: Callable[[], None], name: str = "timer") -> None:
        """Run `fn` every `period_s` seconds on its own thread until stop."""

        def loop() -> None:
            while not self.stop_event.wait(period_s):
                try:
                    fn()
                except Exception as exc:
                    self._warn.warning(f"timer:{name}", "%s failed: %r", name, exc)

        thread = threading.Thread(target=loop, name=f"{self.name}:{name}", daemon=True)
        thread.start()
        self._threads.append(thread)

    def stop(self) -> None:
        self.stop_event.set()

    def spin(self) -> None:
        """Block until stopped (signals call `stop()` via `install_signal_handlers`)."""
        while not self.stop_event.wait(0.5):
            pass

    def close(self) -> None:
        """Undeclare everything (advanced subscribers first: zenoh-python #624), close."""
        if self._closed:
            return
        self._closed = True
        self.stop_event.set()
        for worker in self._workers:
            worker.close()
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except Exception as exc:
                log.debug("undeclare failed: %s", exc)
        try:
            self._token.undeclare()
        except Exception as exc:
            log.debug("token undeclare failed: %s", exc)
        if self._owns_session:
            self.session.close()
        self.log.info("node %s stopped", self.name)

    def __enter__(self) -> Node:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _error_payload(text: str) -> bytes:
    return msgspec.json.encode(m.ErrorReply(error=text))


def error_text(payload: bytes) -> str:
    """The text of an error reply (ours are ErrorReply JSON; others raw text)."""
    try:
        return msgspec.json.decode(payload, type=m.ErrorReply).error
    except (msgspec.DecodeError, msgspec.ValidationError):
        return payload.decode("utf-8", "replace")


def call_service(
    session: zenoh.Session, key: str, service: keys.Service, request: m.Message, timeout: float
) -> Any:
    """Send one query and decode the first reply with the service's reply type."""
    codec = service.codec
    replies = session.get(
        key,
        payload=codec.encode(request),
        encoding=zenoh.Encoding(codec.encoding(service.request)),
        timeout=timeout,
    )
    for reply in replies:
        if reply.ok is not None:
            try:
                return codec.decode(reply.ok.payload.to_bytes(), service.reply)
            except (msgspec.DecodeError, msgspec.ValidationError) as exc:
                raise ServiceError(f"{key}: malformed reply: {exc}") from None
        raise ServiceError(f"{key}: {error_text(reply.err.payload.to_bytes())}")
    raise ServiceError(f"{key}: no reply within {timeout:g} s (is the service running?)")


def live_instances(session: zenoh.Session, key: str, timeout: float = 2.0) -> set[str]:
    """Instance ids of the liveliness tokens matching `key` (`.../nodes/<name>/*`)."""
    found: set[str] = set()
    for reply in session.liveliness().get(key, timeout=timeout):
        if reply.ok is None:
            continue
        parts = keys.split_absolute(str(reply.ok.key_expr))
        match = keys.NODES.match(parts[1]) if parts else None
        if match is not None:
            found.add(match["instance"])
    return found


def install_signal_handlers(stop: threading.Event) -> None:
    """SIGINT/SIGTERM set `stop`, so the main loop can shut down cleanly.

    The Python-level handler does nothing: a handler runs in the main thread
    between two bytecodes, and one that took a lock (`Event.set`, logging) could
    interrupt that same thread while it held the lock and deadlock it. This
    happened: a service that got SIGTERM while its main thread sat in
    `stop.wait()` hung forever. Instead the C-level handler writes the signal
    number to a pipe (`signal.set_wakeup_fd`) and a watcher thread sets `stop`.
    Call from the main thread.
    """
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    wanted = {int(signal.SIGINT), int(signal.SIGTERM)}

    def watch() -> None:
        while True:
            data = os.read(read_fd, 64)
            for signum in data:
                if signum in wanted:
                    log.info("received %s, stopping", signal.Signals(signum).name)
                    stop.set()

    threading.Thread(target=watch, name="signals", daemon=True).start()

    def handler(_signum: int, _frame: object) -> None:
        """Nothing here (see above): the wakeup fd carries the signal."""

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def new_goal_id() -> str:
    return uuid.uuid4().hex[:12]
