"""The node runtime: one Zenoh session per process, typed pub/sub, queryables.

Everything a service or a tool needs from Zenoh lives here, written once;
the raw session stays private to this module (issue 16):

* every declaration returns a handle (`Subscription`, `Publisher`,
  `RawPublisher`, `Queryable`, `Token`) with an idempotent `close()`, also
  a context manager, so one key can be dropped while the node runs;
* tools get a raw side (`subscribe_raw`, `raw_publisher`, `query`,
  `call_key`, `node_instances`) on absolute keys, and `probe=True` nodes
  that declare no token and publish no diagnostics, so looking at the
  robot does not change what `nodes` reports;

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
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, Literal, Self, TypeVar, overload

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
    session: zenoh.Session = result["session"]
    return session


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

    def __init__(self, node: Node, period_s: float, publish: bool = True) -> None:
        """`publish=False` (probes): counters are kept but nothing is put on
        the bus, so a probe stays invisible."""
        self._node = node
        self._period = period_s
        self._lock = threading.Lock()
        self.level: m.DiagnosticLevel = "OK"
        self.message = "running"
        self.values: dict[str, m.DiagnosticValue] = {}
        self._pub = node.publisher(keys.DIAGNOSTICS, node=node.name) if publish else None

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
        if self._pub is None:
            return
        # Samples a worker dropped for newer ones ("latest" delivery: expected) or
        # because its queue was full (a handler slower than its input).
        workers = list(self._node._workers)  # handles may close meanwhile
        dropped = {f"dropped {w.label}": w.dropped for w in workers if w.dropped}
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


# --- handles: what a node declared, closable one by one -------------------------------


class Handle:
    """Something a node declared on the bus; `close()` takes it back.

    Services and tools stop listening to one key, or stop answering one
    service, without closing the whole node and without touching the raw
    Zenoh session (the model is rclpy's `destroy_subscription` and dimos'
    disposables). `close()` is idempotent and thread-safe, removes the
    handle from the node's bookkeeping and stops its worker thread, if any;
    `Node.close()` closes whatever is still open. Usable as a context
    manager.
    """

    _first_on_node_close = False
    """Undeclared before the others when the node closes (advanced
    subscribers: zenoh-python #624)."""
    _drop_pending = True
    """Whether work still queued on the worker is dropped at close (samples)
    or done first (queries, which would otherwise be left without a reply)."""

    def __init__(self, node: Node, key: str) -> None:
        self.key = key
        """The absolute key expression this handle was declared on."""
        self._node = node
        self._entity: Any = None
        self._worker: _Worker | None = None
        self._lock = threading.Lock()
        self._closed = False

    def _attach(self, entity: Any, worker: _Worker | None = None) -> None:
        """Record the declared Zenoh entity and register with the node (last
        step of a subclass constructor: a half-built handle is never closed)."""
        self._entity = entity
        self._worker = worker
        self._node._adopt(self)

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Undeclare (safe twice, safe after the node closed); stop the worker."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._node._forget(self)
        if self._entity is not None:
            try:
                self._entity.undeclare()
            except Exception as exc:  # ZError: already gone with its session
                log.debug("undeclare %s failed: %s", self.key, exc)
        if self._worker is not None:
            self._worker.close(drop_pending=self._drop_pending)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"<{type(self).__name__} {self.key} {state}>"


class Subscription(Handle):
    """A subscriber (typed, raw, or a liveliness watch); deliveries stop at `close()`.

    Samples already queued for a worker are dropped; a callback already
    running in Zenoh's thread finishes, none starts after `close()` returns.
    """

    def __init__(self, node: Node, key: str) -> None:
        super().__init__(node, key)

    def _declare(self, on_sample: Callable[[zenoh.Sample], None], *, history: str | None,
                 worker: _Worker | None = None) -> None:
        """Declare the subscriber. `history`: None (plain), "probe" (late joiners
        get the latched value, nothing else is declared) or "full" (also
        recovery and subscriber detection, as services use)."""
        session = self._node._session

        def guarded(sample: zenoh.Sample) -> None:
            if not self._closed:
                on_sample(sample)

        try:
            if history is None:
                entity: Any = session.declare_subscriber(self.key, guarded)
            else:
                extra: dict[str, Any] = {}
                if history == "full":
                    extra = {"recovery": zenoh.ext.RecoveryConfig(periodic_queries=None,
                                                                  heartbeat=True),
                             "subscriber_detection": True}
                entity = zenoh.ext.declare_advanced_subscriber(
                    session, self.key, guarded,
                    history=zenoh.ext.HistoryConfig(detect_late_publishers=True,
                                                    max_samples=1),
                    **extra,
                )
                self._first_on_node_close = True
        except BaseException:
            if worker is not None:
                worker.close(drop_pending=True)
            raise
        self._attach(entity, worker)


class Queryable(Handle):
    """A served service; after `close()` callers get no reply from it.

    Requests already queued are still answered before the worker stops.
    """

    _drop_pending = False


class Token(Handle):
    """A liveliness token: the key is alive while the token is open."""

    def __init__(self, node: Node, key: str) -> None:
        super().__init__(node, key)
        self._attach(node._session.liveliness().declare_token(_key_expr(key)))


class _Adopted(Handle):
    """A raw Zenoh entity handed to the node (benchmarks measuring bare Zenoh)."""

    def __init__(self, node: Node, entity: Any) -> None:
        super().__init__(node, str(getattr(entity, "key_expr", "?")))
        self._attach(entity)


def _key_expr(key: str) -> str:
    """`key` checked as a Zenoh key expression: a ValueError naming it, not a ZError."""
    try:
        zenoh.KeyExpr(key)
    except zenoh.ZError as exc:
        raise ValueError(f"{key!r}: not a valid key expression: {exc}") from None
    return key


@dataclass(frozen=True)
class RawReply:
    """One reply to a raw query: payload bytes as sent, whether it is an error."""

    ok: bool
    payload: bytes
    encoding: str
    key: str | None
    """The replying key (None for an error reply)."""
    replier: str | None
    """The zid of the process that answered (None if Zenoh does not say)."""


@dataclass(frozen=True)
class ServiceReply:
    """A decoded service reply and who sent it (`Node.call(..., with_replier=True)`)."""

    value: Any
    replier: str | None
    """The zid of the answering process: its node instance (see `watch_node`)."""


class CallError(ServiceError):
    """A failed call: `reason` is the text without the key (for messages that
    already say which service they called)."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"{key}: {reason}")
        self.key = key
        self.reason = reason


class NoReplyError(CallError):
    """Nobody answered in time: the service is not (yet) declared, or is gone.
    Callers that wait for a starting service retry on this one only."""


# --- typed publishers ----------------------------------------------------------------


HEARTBEAT_S = 0.5
"""Period of a latched publisher's heartbeat after it published (miss detection)."""


class Publisher(Handle, Generic[T]):
    """Puts messages of one catalogue topic on one concrete key."""

    def __init__(self, node: Node, topic: keys.Topic, key: str) -> None:
        super().__init__(node, key)
        self.topic = topic
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
                node._session, key,
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
            self._plain = node._session.declare_publisher(key, **options)
            self._z = self._plain
        self._encode = topic.codec.encode
        self._put = self._z.put
        self._attach(self._z)

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
        return _matching(self._plain)


class RawPublisher(Handle):
    """Puts already encoded bytes on any concrete key (tools: `buddybot pub`).

    Congestion control DROP like every publisher of the robot; the encoding
    is set once at declaration.
    """

    def __init__(self, node: Node, key: str, encoding: str,
                 priority: str = "data", express: bool = False) -> None:
        super().__init__(node, key)
        self.encoding = encoding
        self._z = node._session.declare_publisher(
            key, encoding=zenoh.Encoding(encoding), congestion_control=_CONGESTION["drop"],
            priority=_PRIORITY[priority], express=express,
        )
        self._put = self._z.put
        self._attach(self._z)

    def put(self, payload: bytes) -> None:
        self._put(payload)

    def has_subscribers(self) -> bool:
        """Whether a subscriber matches the key right now."""
        return _matching(self._z)

    def wait_for_subscribers(self, timeout: float, stop: threading.Event | None = None
                             ) -> bool:
        """Wait until a subscriber matches (so a single put is not lost to
        discovery); False after `timeout` or when `stop` is set first."""
        matched = threading.Event()

        def on_status(status: zenoh.MatchingStatus) -> None:
            if status.matching:
                matched.set()

        listener = self._z.declare_matching_listener(on_status)
        try:
            end = time.monotonic() + timeout
            while not matched.is_set() and not self.has_subscribers():
                left = end - time.monotonic()
                if left <= 0 or (stop is not None and stop.is_set()):
                    return False
                matched.wait(min(left, 0.1))  # 0.1: stay responsive to `stop`
            return True
        finally:
            listener.undeclare()


def _matching(publisher: zenoh.Publisher) -> bool:
    """Whether a subscriber matches `publisher`. The 1.x stubs type
    `matching_status` as a bool, but it is a MatchingStatus: read either."""
    status: Any = publisher.matching_status
    return bool(getattr(status, "matching", status))


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
        """Queue an item; when full the oldest is dropped (counted). Ignored
        once closed (a late sample of a closed subscription)."""
        with self._cond:
            if self._closed:
                return
            if len(self._items) == self._items.maxlen:
                self.dropped += 1
            self._items.append(item)
            self._cond.notify()

    def offer(self, *item: Any) -> bool:
        """Queue an item unless full: False means the caller must refuse it
        (queries: a dropped query would leave its caller with no answer)."""
        with self._cond:
            if self._closed or len(self._items) == self._items.maxlen:
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

    def close(self, timeout: float = 2.0, drop_pending: bool = False) -> None:
        """Stop after the queued items (or without them: `drop_pending`)."""
        with self._cond:
            self._closed = True
            if drop_pending:
                self._items.clear()
            self._cond.notify()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)


# --- the node ----------------------------------------------------------------------


class Node:
    """One process's connection to the robot, and its only door to Zenoh.

    Every declaration returns a handle that can be closed on its own
    (`Subscription`, `Publisher`/`RawPublisher`, `Queryable`, `Token`);
    use the node as a context manager, or call `close()`, to close the
    rest. `spin()` blocks until SIGINT/SIGTERM (or `stop()`).

    Services use catalogue entries (`subscribe`, `publisher`, `serve`,
    `call`). Probing tools use the raw side (`subscribe_raw`,
    `raw_publisher`, `query`, `call_key`, `node_instances`) on absolute
    keys, with `probe=True` so that they are not seen as nodes.
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
        probe: bool = False,
        stamp_window_s: tuple[float, float] = (limits.STAMP_PAST_S, limits.STAMP_FUTURE_S),
        config: zenoh.Config | None = None,
    ) -> None:
        """`unique`: refuse to start (DuplicateNodeError) when another process
        already runs a node of this name on this robot (services set it; tools
        and tests that open several probes do not). `probe`: a tool looking at
        the robot, not a part of it: no liveliness token (`nodes` does not list
        it), no duplicate check, no diagnostics on the bus. `stamp_window_s`:
        how far (past, future) a received `stamp_ns` may lie from its arrival
        time. `config`: a ready Zenoh config instead of `connect`/`zenoh_config_file`
        (e.g. a bounded connect timeout); `session`: an already open session,
        which `close()` leaves open."""
        if probe and unique:
            raise ValueError("a probe does not announce itself: it cannot be unique")
        self.name = name
        self.robot = robot
        self.prefix = keys.prefix(robot)
        self.probe = probe
        self.log = logging.getLogger(f"buddybot.{name}")
        self.stop_event = stop_event or threading.Event()
        self._handles: list[Handle] = []
        self._handles_lock = threading.Lock()
        self._workers: list[_Worker] = []
        self._threads: list[threading.Thread] = []
        self._closed = False
        self._warn = RateLimitedLog(self.log)
        self._stamp_window = stamp_window_s
        if session is None:
            if config is None:
                config = zenoh_config(connect=connect, base_file=zenoh_config_file)
            opened = open_session(config, self.stop_event, "router at " + ", ".join(connect))
            if opened is None:
                raise KeyboardInterrupt("stopped while waiting for the router")
            self._owns_session = True
            session = opened
        else:
            self._owns_session = False
        self._session: zenoh.Session = session
        """The raw session: private. Everything outside this module goes
        through the node's methods and handles (issue 16)."""
        self.instance = str(session.info.zid())
        """This process's identity on the bus (its Zenoh session id)."""
        if unique:
            self._refuse_duplicate()
        self.diagnostics = Diagnostics(self, diagnostics_period_s, publish=not probe)
        self._token: Token | None = None
        if not probe:
            self._token = self.declare_token(
                self.key(keys.NODES, node=name, instance=self.instance))
            self.watch_node(name, self._on_own_instances)
            self.every(diagnostics_period_s, self.diagnostics.publish, name="diagnostics")
        self.log.log(logging.DEBUG if probe else logging.INFO,
                     "node %s up (robot %s, instance %s)", name, robot, self.instance)

    # -- bookkeeping of handles --

    def _adopt(self, handle: Handle) -> None:
        with self._handles_lock:
            self._handles.append(handle)
            if handle._worker is not None:
                self._workers.append(handle._worker)

    def _forget(self, handle: Handle) -> None:
        with self._handles_lock:
            if handle in self._handles:
                self._handles.remove(handle)
            if handle._worker is not None and handle._worker in self._workers:
                self._workers.remove(handle._worker)

    def _own(self, entity: Any) -> Handle:
        """Take a raw Zenoh entity into the node's bookkeeping (closed with the
        node). Only for benchmarks that measure bare Zenoh against the node."""
        return _Adopted(self, entity)

    @property
    def handles(self) -> list[Handle]:
        """The handles still open (a copy), oldest first: for tests and debugging."""
        with self._handles_lock:
            return list(self._handles)

    # -- identity --

    def _refuse_duplicate(self) -> None:
        others = self.live_instances(self.key(keys.NODES, node=self.name))
        others.discard(self.instance)
        if others:
            if self._owns_session:
                self._session.close()
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

    def connected(self) -> bool:
        """Whether the session has a router right now (False while it
        reconnects, and once the node is closed)."""
        try:
            return bool(self._session.info.routers_zid())
        except Exception as exc:  # ZError from a closed session
            log.debug("router check failed: %r", exc)
            return False

    # -- liveliness --

    def declare_token(self, key: str) -> Token:
        """A liveliness token on an absolute key, alive until closed (or until
        this process dies: the router drops it then)."""
        return Token(self, key)

    def watch_node(
        self, name: str, on_change: Callable[[frozenset[str]], None]
    ) -> Subscription:
        """Call `on_change(instances)` with the set of live instances (zids) of
        node `name` now and whenever it changes: one source of truth for "is X
        running", from liveliness tokens only (runs in Zenoh's thread: be quick).
        Close the returned handle to stop watching."""
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

        handle = Subscription(self, self.key(keys.NODES, node=name))

        def guarded(sample: zenoh.Sample) -> None:
            if not handle.closed:
                on_token(sample)

        handle._attach(self._session.liveliness().declare_subscriber(
            handle.key, guarded, history=True))
        return handle

    def live_instances(self, key: str, timeout: float = 2.0) -> set[str]:
        """Instance ids of the liveliness tokens matching `key` (an absolute
        `.../nodes/<name>/*`), asked once (probes do not hold a watch)."""
        return live_instances(self._session, key, timeout)

    def node_instances(self, *, all_robots: bool = False, timeout: float = 2.0
                       ) -> dict[str, set[str]]:
        """Live node names -> their instances (zids), from liveliness tokens:
        this node's robot, or every robot (names then read `robot/name`).
        More than one instance of a name is a duplicate."""
        robot = "*" if all_robots else self.robot
        key = f"{keys.PREFIX_ROOT}/{robot}/{keys.NODES.wildcard()}"
        found: dict[str, set[str]] = {}
        for reply in self._session.liveliness().get(key, timeout=timeout):
            if reply.ok is None:
                continue
            parts = keys.split_absolute(str(reply.ok.key_expr))
            match = keys.NODES.match(parts[1]) if parts else None
            if parts is None or match is None:
                continue
            name = f"{parts[0]}/{match['node']}" if all_robots else match["node"]
            found.setdefault(name, set()).add(match["instance"])
        return found

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

    def raw_publisher(self, key: str, encoding: str) -> RawPublisher:
        """A publisher of already encoded bytes on an absolute key, which need
        not be in the catalogue (tools: `buddybot pub`). Nothing is validated:
        the receivers' decoders are the guard."""
        if "*" in key:
            raise ValueError(f"cannot publish on a wildcard key {key}")
        return RawPublisher(self, _key_expr(key), encoding)

    def subscribe(
        self,
        topic: keys.Topic,
        callback: Callable[[Any, str], None],
        *,
        delivery: Delivery = "inline",
        queue_size: int = 64,
        history: bool | None = None,
        **params: str,
    ) -> Subscription:
        """Call `callback(message, relative_key)` for each valid sample, until
        the returned handle (or the node) is closed.

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

        worker = self._worker_for(delivery, callback, queue_size, on_error, topic.pattern)
        sink: Callable[..., None] = callback if worker is None else worker.submit
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
        handle = Subscription(self, key)
        handle._declare(on_sample, history="full" if use_history else None, worker=worker)
        return handle

    def subscribe_raw(
        self,
        key_expr: str,
        callback: Callable[[str, bytes, str], None],
        *,
        history: bool = False,
        delivery: Delivery = "inline",
        queue_size: int = 64,
    ) -> Subscription:
        """Call `callback(key, payload, encoding)` for each sample on an absolute
        key expression (wildcards allowed, catalogue or not), undecoded: for
        tools (`echo`, `hz`) and monitors that decode, or only count, themselves.

        `history`: also get the latched value of every matching publisher at
        once (an advanced subscriber that declares nothing else, so a probe
        stays unseen). Deletions are not delivered. A failing callback is
        counted and logged, never fatal.
        """
        key_expr = _key_expr(key_expr)

        def on_error(exc: BaseException) -> None:
            self.diagnostics.increment("callback_errors")
            self._warn.warning(f"cb:{key_expr}", "handler for %s failed: %r", key_expr, exc)

        worker = self._worker_for(delivery, callback, queue_size, on_error, key_expr)
        sink: Callable[..., None] = callback if worker is None else worker.submit
        put_kind = zenoh.SampleKind.PUT

        def on_sample(sample: zenoh.Sample) -> None:
            if sample.kind != put_kind:
                return
            try:
                sink(str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding))
            except Exception as exc:  # only inline handlers raise here
                on_error(exc)

        handle = Subscription(self, key_expr)
        handle._declare(on_sample, history="probe" if history else None, worker=worker)
        return handle

    def _worker_for(self, delivery: Delivery, callback: Callable[..., None], queue_size: int,
                    on_error: Callable[[BaseException], None], label: str) -> _Worker | None:
        """The worker thread of a non-inline delivery (owned by its handle)."""
        if delivery == "inline":
            return None
        return _Worker(f"{self.name}:{label}", callback, delivery == "latest", queue_size,
                       on_error, label=label)

    # -- services --

    def serve(
        self,
        service: keys.Service,
        handler: Callable[[Any], m.Message],
        *,
        queue_size: int = 16,
        **params: str,
    ) -> Queryable:
        """Answer queries on a catalogue service with `handler(request) -> reply`,
        until the returned handle (or the node) is closed.

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
        handle = Queryable(self, key)

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
                        "service closing" if handle.closed else
                        f"busy: {queue_size} requests already waiting on {service.pattern}"))

        try:
            queryable = self._session.declare_queryable(key, on_query)
        except BaseException:
            worker.close()
            raise
        handle._attach(queryable, worker)
        return handle

    @overload
    def call(self, service: keys.Service, request: m.Message, *, timeout: float = ...,
             with_replier: Literal[False] = ..., **params: str) -> Any: ...

    @overload
    def call(self, service: keys.Service, request: m.Message, *, timeout: float = ...,
             with_replier: Literal[True], **params: str) -> ServiceReply: ...

    def call(
        self, service: keys.Service, request: m.Message, *, timeout: float = 5.0,
        with_replier: bool = False, **params: str,
    ) -> Any:
        """Query a service; returns the decoded reply (a ServiceReply naming the
        answering instance with `with_replier`). Raises ServiceError: a
        NoReplyError when nobody answered, a CallError otherwise."""
        return self.call_key(self.key(service, **params), service, request, timeout=timeout,
                             with_replier=with_replier)

    def call_key(
        self, key: str, service: keys.Service, request: m.Message, *, timeout: float = 5.0,
        with_replier: bool = False,
    ) -> Any:
        """`call` on an absolute key (tools: `buddybot call`, other robots)."""
        codec = service.codec
        replies = self.query(key, codec.encode(request),
                             encoding=codec.encoding(service.request), timeout=timeout)
        reply = _service_reply(replies, key, service, timeout)
        return reply if with_replier else reply.value

    def query(
        self, key: str, payload: bytes | None = None, *, encoding: str | None = None,
        timeout: float = 5.0,
    ) -> Iterator[RawReply]:
        """Send one query on an absolute key now; iterate its replies as they
        come (ends when all repliers answered or at `timeout`). The query
        leaves at once, so many can be pending together; payloads go as they
        are (tests and tools probing a service with arbitrary bytes)."""
        options: dict[str, Any] = {"timeout": timeout}
        if payload is not None:
            options["payload"] = payload
        if encoding is not None:
            options["encoding"] = zenoh.Encoding(encoding)
        replies = self._session.get(_key_expr(key), **options)
        return (_raw_reply(reply) for reply in replies)

    # -- timers, lifetime --

    def every(self, period_s: float, fn: Callable[[], object], name: str = "timer") -> None:
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
        """Close every handle still open, then the session (if the node opened it).

        Advanced subscribers go first (zenoh-python #624), then the rest,
        newest first; the node's own token last, then the session.
        """
        if self._closed:
            return
        self._closed = True
        self.stop_event.set()
        with self._handles_lock:
            left = list(reversed(self._handles))
        ordered = ([h for h in left if h._first_on_node_close]
                   + [h for h in left if not h._first_on_node_close and h is not self._token])
        if self._token is not None:
            ordered.append(self._token)
        for handle in ordered:
            handle.close()
        if self._owns_session:
            self._session.close()
        self.log.log(logging.DEBUG if self.probe else logging.INFO,
                     "node %s stopped", self.name)

    def __enter__(self) -> Node:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _raw_reply(reply: zenoh.Reply) -> RawReply:
    source = reply.replier_id  # the answering entity; its zid is its process
    replier = None if source is None else str(source.zid)
    if reply.ok is not None:
        sample = reply.ok
        return RawReply(ok=True, payload=sample.payload.to_bytes(),
                        encoding=str(sample.encoding), key=str(sample.key_expr),
                        replier=replier)
    err = reply.err
    assert err is not None  # a reply is either ok or err
    return RawReply(ok=False, payload=err.payload.to_bytes(), encoding=str(err.encoding),
                    key=None, replier=replier)


def _service_reply(replies: Iterator[RawReply], key: str, service: keys.Service,
                   timeout: float) -> ServiceReply:
    """The first reply decoded with the service's reply type, or the CallError."""
    for reply in replies:
        if not reply.ok:
            raise CallError(key, error_text(reply.payload))
        try:
            return ServiceReply(service.codec.decode(reply.payload, service.reply), reply.replier)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise CallError(key, f"malformed reply: {exc}") from None
    raise NoReplyError(key, f"no reply within {timeout:g} s (is the service running?)")


def _error_payload(text: str) -> bytes:
    return msgspec.json.encode(m.ErrorReply(error=text))


def error_text(payload: bytes) -> str:
    """The text of an error reply (ours are ErrorReply JSON; others raw text)."""
    try:
        return msgspec.json.decode(payload, type=m.ErrorReply).error
    except (msgspec.DecodeError, msgspec.ValidationError):
        return payload.decode("utf-8", "replace")


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
