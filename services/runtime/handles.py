"""What a node declares on the bus, as handles that can be closed one by one.

Publishers, subscriptions, queryables and liveliness tokens; the workers
that run slow handlers off Zenoh's thread; and the shapes of raw and
decoded service replies. `Node` (node.py) creates them; nothing else
needs a raw Zenoh session.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, Literal, Self, TypeVar

import msgspec
import zenoh
import zenoh.ext

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import (
    CallError,
    NoReplyError,
)

if TYPE_CHECKING:
    from buddybot.runtime.node import Node

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
