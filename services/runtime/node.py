"""The node runtime: one Zenoh session per process, typed pub/sub, queryables.

Everything a service or a tool needs from Zenoh lives here, written once;
the raw session stays private to this module, so every use of it is one
of the node's methods or handles. Every declaration returns a handle with
an idempotent `close()`; tools get a raw side on absolute keys and
`probe=True` nodes; the session is a client of the router endpoints; a
liveliness token says the node is alive; nothing uses congestion control
BLOCK; no sample can freeze or bloat a handler; latched topics are
recovered by late joiners; slow handlers run on workers, never in Zenoh's
callback thread.

Each rule and its why: docs/core.md, 'The node runtime's rules'.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from typing import Any, Literal, TypeVar, overload

import msgspec
import zenoh
import zenoh.ext

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import limits
from buddybot.runtime.diagnostics import Diagnostics, RateLimitedLog
from buddybot.runtime.errors import (
    BUSY_PREFIX,
    CallError,
    DuplicateNodeError,
    NoReplyError,
    ServiceError,
)
from buddybot.runtime.handles import (
    Adopted,
    Delivery,
    Gate,
    Handle,
    Publisher,
    Queryable,
    RawPublisher,
    RawQuery,
    RawReply,
    ServiceReply,
    Subscription,
    Token,
    Worker,
    error_payload,
    error_text,
    raw_reply,
    service_reply,
)
from buddybot.runtime.session import (
    MAX_MESSAGE_BYTES,
    WAIT_BEFORE_CLOSE_US,
    live_instances,
    open_session,
    zenoh_config,
)
from buddybot.runtime.signals import install_signal_handlers

__all__ = [
    "HEARTBEAT_S", "MAX_MESSAGE_BYTES", "WAIT_BEFORE_CLOSE_US", "CallError", "Delivery",
    "Diagnostics", "DuplicateNodeError", "Handle", "NoReplyError", "Node", "Publisher",
    "Queryable", "RateLimitedLog", "RawPublisher", "RawReply", "ServiceError", "ServiceReply",
    "Subscription", "Token", "error_text", "install_signal_handlers", "live_instances",
    "new_goal_id", "open_session", "zenoh_config",
]

log = logging.getLogger("buddybot.node")

H = TypeVar("H", bound=Handle)

_CONGESTION = {"drop": zenoh.CongestionControl.DROP}
_PRIORITY = {
    "real_time": zenoh.Priority.REAL_TIME,
    "interactive_high": zenoh.Priority.INTERACTIVE_HIGH,
    "data": zenoh.Priority.DATA,
    "background": zenoh.Priority.BACKGROUND,
}

HEARTBEAT_S = 0.5
"""Period of a latched publisher's heartbeat after it published (miss detection)."""


def _key_expr(key: str) -> str:
    """`key` checked as a Zenoh key expression: a ValueError naming it, not a ZError."""
    try:
        zenoh.KeyExpr(key)
    except zenoh.ZError as exc:
        raise ValueError(f"{key!r}: not a valid key expression: {exc}") from None
    return key


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
        through the node's methods and handles."""
        self.instance = str(session.info.zid())
        """This process's identity on the bus (its Zenoh session id)."""
        if unique:
            self._refuse_duplicate()
        self.diagnostics = Diagnostics(
            name, diagnostics_period_s,
            None if probe else self.publisher(keys.DIAGNOSTICS, node=name), self._dropped)
        self._token: Token | None = None
        if not probe:
            self._token = self.declare_token(
                self.key(keys.NODES, node=name, instance=self.instance))
            self.watch_node(name, self._on_own_instances)
            self.every(diagnostics_period_s, self.diagnostics.publish, name="diagnostics")
            self._serve_node_info()
        self.log.log(logging.DEBUG if probe else logging.INFO,
                     "node %s up (robot %s, instance %s)", name, robot, self.instance)

    # -- bookkeeping of handles --

    def _track(self, handle: H) -> H:
        """Keep a handle just declared until it (or the node) closes; its
        `on_close` is `_forget`."""
        with self._handles_lock:
            self._handles.append(handle)
        return handle

    def _forget(self, handle: Handle) -> None:
        with self._handles_lock:
            if handle in self._handles:
                self._handles.remove(handle)

    def _dropped(self) -> list[tuple[str, int]]:
        """(label, dropped samples) of each open handle's worker, for diagnostics."""
        return [(h.worker.label, h.worker.dropped) for h in self.handles if h.worker]

    def _own(self, entity: Any) -> Handle:
        """Take a raw Zenoh entity into the node's bookkeeping (closed with the
        node). Only for benchmarks that measure bare Zenoh against the node."""
        return self._track(Adopted(str(getattr(entity, "key_expr", "?")), entity, self._forget))

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
        entity = self._session.liveliness().declare_token(_key_expr(key))
        return self._track(Token(key, entity, self._forget))

    def watch_node(
        self, name: str, on_change: Callable[[frozenset[str]], None]
    ) -> Subscription:
        """Call `on_change(instances)` with the set of live instances (zids) of
        node `name` now and whenever it changes: one source of truth for "is X
        running", from liveliness tokens only (runs in Zenoh's thread: be quick).
        Close the returned handle to stop watching."""
        alive: set[str] = set()
        lock = threading.Lock()

        def on_token(_node: str, instance: str, up: bool) -> None:
            with lock:
                if up:
                    alive.add(instance)
                else:
                    alive.discard(instance)
                current = frozenset(alive)
            on_change(current)

        return self.watch_nodes(on_token, name=name)

    def watch_nodes(
        self, on_token: Callable[[str, str, bool], None], *, name: str = "*"
    ) -> Subscription:
        """Call `on_token(node, instance, alive)` for every liveliness token of the
        nodes matching `name` (every node by default) that exists now, and for
        every one that appears or goes away later (a process that ends, crashes
        or is killed loses its token). Runs in Zenoh's thread: be quick."""

        def on_any(key: str, alive: bool) -> None:
            found = keys.NODES.match(self.relative(key))
            if found is not None:
                on_token(found["node"], found["instance"], alive)

        return self.watch_tokens(self.key(keys.NODES, node=name), on_any)

    def watch_tokens(self, key_expr: str, on_token: Callable[[str, bool], None]
                     ) -> Subscription:
        """Call `on_token(key, alive)` for every liveliness token matching the
        absolute `key_expr` that exists now, and whenever one appears or goes
        away (its session closed or died). A failing callback is logged, never
        fatal. Runs in Zenoh's thread: be quick."""
        put = zenoh.SampleKind.PUT
        key_expr = _key_expr(key_expr)

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                on_token(str(sample.key_expr), sample.kind == put)
            except Exception as exc:
                self._warn.warning(f"watch:{key_expr}", "token watcher for %s failed: %r",
                                   key_expr, exc)

        gate = Gate()
        entity = self._session.liveliness().declare_subscriber(
            key_expr, gate.guard(on_sample), history=True)
        return self._track(Subscription(key_expr, entity, self._forget, gate=gate))

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
        return keys.relative(self.robot, key)

    # -- publish / subscribe --

    def publisher(self, topic: keys.Topic, /, **params: str) -> Publisher[Any]:
        return self.publisher_on(topic, self.key(topic, **params))

    def publisher_on(self, topic: keys.Topic, key: str) -> Publisher[Any]:
        """A publisher of a catalogue topic on an absolute concrete key (`bag
        play` puts recorded keys back, possibly on another robot's prefix)."""
        if "*" in key:
            raise ValueError(f"cannot publish on a wildcard key {key}")
        qos = topic.qos
        options: dict[str, Any] = {
            "encoding": zenoh.Encoding(topic.encoding),
            "congestion_control": _CONGESTION[qos.congestion],
            "priority": _PRIORITY[qos.priority],
            "express": qos.express,
        }
        entity: Any
        if topic.latched:
            entity = zenoh.ext.declare_advanced_publisher(
                self._session, key,
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
            entity = self._session.declare_publisher(key, **options)
        return self._track(Publisher(topic, key, entity, self._forget))

    def raw_publisher(self, key: str, encoding: str, *, cache: int | None = None
                      ) -> RawPublisher:
        """A publisher of already encoded bytes on an absolute key, which need
        not be in the catalogue (tools: `buddybot pub`). Nothing is validated:
        the receivers' decoders are the guard. `cache`: keep the last `cache`
        samples for late joiners (an advanced publisher, as latched topics and
        rmw_zenoh's transient-local publishers are, with publisher detection and
        a sporadic heartbeat so a missed sample is fetched again)."""
        if "*" in key:
            raise ValueError(f"cannot publish on a wildcard key {key}")
        options: dict[str, Any] = {
            "encoding": zenoh.Encoding(encoding), "congestion_control": _CONGESTION["drop"],
            "priority": _PRIORITY["data"], "express": False}
        entity: Any
        if cache is None:
            entity = self._session.declare_publisher(_key_expr(key), **options)
        else:
            entity = zenoh.ext.declare_advanced_publisher(
                self._session, _key_expr(key), cache=zenoh.ext.CacheConfig(max_samples=cache),
                publisher_detection=True,
                sample_miss_detection=zenoh.ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=HEARTBEAT_S),
                **options)
        return self._track(RawPublisher(key, encoding, entity, self._forget))

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
        return self._subscriber(key, on_sample, history="full" if use_history else None,
                                worker=worker)

    def subscribe_raw(
        self,
        key_expr: str,
        callback: Callable[[str, bytes, str], None],
        *,
        history: bool = False,
        recover: bool = False,
        delivery: Delivery = "inline",
        queue_size: int = 64,
        remote_only: bool = False,
    ) -> Subscription:
        """Call `callback(key, payload, encoding)` for each sample on an absolute
        key expression (wildcards allowed, catalogue or not), undecoded: for
        tools (`echo`, `hz`) and monitors that decode, or only count, themselves.

        `history`: also get the latched value of every matching publisher at
        once (an advanced subscriber that declares nothing else, so a probe
        stays unseen). That alone loses a latched sample dropped on the way
        (state keys drop under congestion) if it was published after its
        publisher's cache was asked: `recover` (implies `history`) subscribes
        as `subscribe` does to latched topics, so the publisher's heartbeat
        reveals the gap and the sample is fetched from its cache; it declares
        more (a heartbeat subscriber, subscriber detection), so a probe that
        must stay unseen goes without. Deletions are not delivered. A failing
        callback is counted and logged, never fatal. `remote_only`: samples
        this node publishes itself are not delivered (a bridge that both
        publishes and takes a key must not hear its own samples back).
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

        mode = "full" if recover else "probe" if history else None
        return self._subscriber(key_expr, on_sample, history=mode, worker=worker,
                                remote_only=remote_only)

    def _subscriber(self, key: str, on_sample: Callable[[zenoh.Sample], None], *,
                    history: str | None, worker: Worker | None,
                    remote_only: bool = False) -> Subscription:
        """Declare a subscriber and track its handle. `history`: None (plain),
        "probe" (late joiners get the latched value, nothing else is declared)
        or "full" (also recovery and subscriber detection, as services use).
        The worker is stopped if the declaration fails."""
        gate = Gate()
        guarded = gate.guard(on_sample)
        try:
            if history is None:
                origin = {"allowed_origin": zenoh.Locality.REMOTE} if remote_only else {}
                entity: Any = self._session.declare_subscriber(key, guarded, **origin)
            else:
                extra: dict[str, Any] = {}
                if history == "full":
                    extra = {"recovery": zenoh.ext.RecoveryConfig(periodic_queries=None,
                                                                  heartbeat=True),
                             "subscriber_detection": True}
                entity = zenoh.ext.declare_advanced_subscriber(
                    self._session, key, guarded,
                    history=zenoh.ext.HistoryConfig(detect_late_publishers=True,
                                                    max_samples=1),
                    **extra,
                )
        except BaseException:
            if worker is not None:
                worker.close(drop_pending=True)
            raise
        return self._track(Subscription(key, entity, self._forget, gate=gate, worker=worker,
                                        advanced=history is not None))

    def _worker_for(self, delivery: Delivery, callback: Callable[..., None], queue_size: int,
                    on_error: Callable[[BaseException], None], label: str) -> Worker | None:
        """The worker thread of a non-inline delivery (owned by its handle)."""
        if delivery == "inline":
            return None
        return Worker(f"{self.name}:{label}", callback, delivery == "latest", queue_size,
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
                query.reply_err(error_payload(f"bad {service.request.__name__}: {text}"))
                return
            try:
                reply = handler(request)
            except Exception as exc:
                self.log.exception("handler for %s failed", key)
                query.reply_err(error_payload(f"{type(exc).__name__}: {limits.clip(exc)}"))
                return
            query.reply(key, codec.encode(reply), encoding=reply_encoding)

        def on_error(exc: BaseException) -> None:
            self.log.error("query handling on %s failed: %r", key, exc)

        worker = Worker(f"{self.name}:{service.pattern}", answer, False, queue_size, on_error,
                        label=service.pattern)
        # The gate only names the refusal below: on_query is not guarded by it,
        # so a query arriving while the handle closes still gets an answer.
        gate = Gate()

        def on_query(query: zenoh.Query) -> None:
            # Every query gets an answer: too large or too many at once are
            # refused here at once (Zenoh's thread; replying is quick), never
            # silently dropped.
            payload = query.payload
            if payload is not None and len(payload) > service.max_bytes:
                self.diagnostics.increment("oversized")
                with query:
                    query.reply_err(error_payload(
                        f"request too large: {len(payload)} bytes (limit {service.max_bytes})"))
                return
            if not worker.offer(query):
                self.diagnostics.increment("busy")
                self._warn.warning(f"busy:{key}", "refused a request on %s: busy", key)
                with query:
                    query.reply_err(error_payload(
                        "service closing" if not gate.open else
                        f"{BUSY_PREFIX}{queue_size} requests already waiting on {service.pattern}"))

        try:
            queryable = self._session.declare_queryable(key, on_query)
        except BaseException:
            worker.close()
            raise
        return self._track(Queryable(key, queryable, self._forget, worker=worker, gate=gate))

    def serve_raw(
        self, key_expr: str, handler: Callable[[RawQuery], None], *, queue_size: int = 16,
        complete: bool = False,
    ) -> Queryable:
        """Answer queries on an absolute key expression (wildcards allowed, catalogue
        or not) with `handler(query)` on a worker thread, undecoded: for a bridge
        that speaks another protocol (the ROS 2 services). The handler replies
        with `query.reply`/`reply_err` or not at all; the query is finished when
        it returns unless it called `query.defer()`. A query over the queue is
        refused at once (error reply `busy`); a failing handler is logged and
        its query finished. `complete`: the queryable answers for every key it
        matches, so queries that target complete queryables only (rmw_zenoh's
        clients) reach it."""
        key_expr = _key_expr(key_expr)

        def answer(query: RawQuery) -> None:
            try:
                handler(query)
            finally:
                if not query.deferred:
                    query.finish()

        def on_error(exc: BaseException) -> None:
            self.diagnostics.increment("callback_errors")
            self._warn.warning(f"cb:{key_expr}", "query handler for %s failed: %r",
                               key_expr, exc)

        worker = Worker(f"{self.name}:{key_expr}", answer, False, queue_size, on_error,
                        label=key_expr)
        gate = Gate()

        def on_query(query: zenoh.Query) -> None:
            raw = RawQuery(query)
            if not worker.offer(raw):
                self.diagnostics.increment("busy")
                self._warn.warning(f"busy:{key_expr}", "refused a query on %s: busy",
                                   key_expr)
                raw.reply_err("service closing" if not gate.open else
                              f"{BUSY_PREFIX}{queue_size} requests already waiting")
                raw.finish()

        try:
            queryable = self._session.declare_queryable(key_expr, on_query, complete=complete)
        except BaseException:
            worker.close()
            raise
        return self._track(Queryable(key_expr, queryable, self._forget, worker=worker,
                                     gate=gate))

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
        reply = service_reply(replies, key, service, timeout)
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
        return (raw_reply(reply) for reply in replies)

    # -- introspection (`buddybot node info`, `buddybot topics`) --

    def declared(self) -> m.NodeInfo:
        """What this node has declared and still holds open, from its own handles
        (keys relative to the robot's prefix; liveliness watches left out): the
        truth about this process, not what a catalogue says it should do."""
        publishers: list[str] = []
        subscriptions: list[str] = []
        services: list[str] = []
        liveliness = self.key(keys.NODES, node="*").rsplit("/", 2)[0] + "/"
        for handle in self.handles:
            key = str(handle.key)
            if key.startswith(liveliness):
                continue
            rel = self.relative(key)
            if isinstance(handle, (Publisher, RawPublisher)):
                publishers.append(rel)
            elif isinstance(handle, Subscription):
                subscriptions.append(rel)
            elif isinstance(handle, Queryable):
                services.append(rel)
        return m.NodeInfo(node=self.name, instance=self.instance,
                          publishers=sorted(set(publishers)),
                          subscriptions=sorted(set(subscriptions)),
                          services=sorted(set(services)))

    def node_infos(self, timeout: float) -> list[m.NodeInfo]:
        """Every running node's own report (`declared()`), asked for over the bus;
        replies that do not decode are skipped."""
        found = []
        for reply in self.query(self.key(keys.NODE_INFO, node="*"),
                                keys.NODE_INFO.codec.encode(m.Trigger()), timeout=timeout):
            if not reply.ok:
                continue
            try:
                found.append(keys.NODE_INFO.codec.decode(reply.payload, m.NodeInfo))
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue
        return found

    def _serve_node_info(self) -> Queryable:
        """Every node answers `node_info/<name>` with `declared()`."""
        return self.serve(keys.NODE_INFO, lambda _request: self.declared(), node=self.name)

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
        ordered = ([h for h in left if h.first_on_node_close]
                   + [h for h in left if not h.first_on_node_close and h is not self._token])
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


def new_goal_id() -> str:
    return uuid.uuid4().hex[:12]
