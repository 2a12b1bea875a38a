"""What a node declares on the bus, as handles that can be closed one by one.

Publishers, subscriptions, queryables and liveliness tokens; the workers
that run slow handlers off Zenoh's thread; and the shapes of raw and
decoded service replies. A handle is given its declared Zenoh entity and
an `on_close` callback by whoever declared it (`Node`, node.py, the model
being rclpy's publisher that receives its entity): it knows nothing of
the node, so the dependency runs one way, node -> handle.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, Literal, Self, TypeVar

import msgspec
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import (
    CallError,
    NoReplyError,
)

log = logging.getLogger("buddybot.node")

T = TypeVar("T", bound=m.Message)
Delivery = Literal["inline", "latest", "queue"]


# --- handles: what a node declared, closable one by one -------------------------------


class Gate:
    """Lets callbacks through until shut, once: the open/closed state of a handle.

    Created before the Zenoh entity, so the callback given to Zenoh can be
    guarded (Zenoh may start one while its entity is being undeclared, and
    a latched history may arrive before the declaration returns), then
    handed to the handle, whose `close()` shuts it.
    """

    def __init__(self) -> None:
        self._open = True
        self._lock = threading.Lock()

    @property
    def open(self) -> bool:
        return self._open

    def shut(self) -> bool:
        """Shut the gate; True only for the call that shut it."""
        with self._lock:
            was_open, self._open = self._open, False
        return was_open

    def guard(self, callback: Callable[..., None]) -> Callable[..., None]:
        """`callback`, called only while the gate is open."""

        def guarded(*args: Any) -> None:
            if self._open:
                callback(*args)

        return guarded


class Handle:
    """Something a node declared on the bus; `close()` takes it back.

    Services and tools stop listening to one key, or stop answering one
    service, without closing the whole node and without touching the raw
    Zenoh session (the model is rclpy's `destroy_subscription` and dimos'
    disposables). `close()` is idempotent and thread-safe: it calls
    `on_close(handle)` (the node forgets it), undeclares the entity and
    stops the worker thread, if any; `Node.close()` closes whatever is
    still open. Usable as a context manager.
    """

    first_on_node_close = False
    """Undeclared before the others when the node closes (advanced
    subscribers: zenoh-python #624)."""
    _drop_pending = True
    """Whether work still queued on the worker is dropped at close (samples)
    or done first (queries, which would otherwise be left without a reply)."""

    def __init__(self, key: str, entity: Any, on_close: Callable[[Handle], None], *,
                 worker: Worker | None = None, gate: Gate | None = None) -> None:
        """`entity`: the declared Zenoh entity (anything with `undeclare()`);
        `worker`: the thread running its handler, stopped at close; `gate`:
        the one guarding its callbacks, if any, shut at close."""
        self.key = key
        """The absolute key expression this handle was declared on."""
        self.worker = worker
        """The thread running this handle's handler (None: inline)."""
        self._entity = entity
        self._on_close = on_close
        self._gate = gate or Gate()

    @property
    def closed(self) -> bool:
        return not self._gate.open

    def close(self) -> None:
        """Undeclare (safe twice, safe after the node closed); stop the worker."""
        if not self._gate.shut():
            return
        self._on_close(self)
        try:
            self._entity.undeclare()
        except Exception as exc:  # ZError: already gone with its session
            log.debug("undeclare %s failed: %s", self.key, exc)
        if self.worker is not None:
            self.worker.close(drop_pending=self._drop_pending)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"<{type(self).__name__} {self.key} {state}>"


class Subscription(Handle):
    """A subscriber (typed, raw, or a liveliness watch); deliveries stop at `close()`.

    Samples already queued for a worker are dropped; a callback already
    running in Zenoh's thread finishes, none starts after `close()` returns
    (the declarer guards it with the `gate` given here).
    """

    def __init__(self, key: str, entity: Any, on_close: Callable[[Handle], None], *,
                 gate: Gate, worker: Worker | None = None, advanced: bool = False) -> None:
        """`advanced`: a zenoh.ext advanced subscriber, undeclared first."""
        super().__init__(key, entity, on_close, worker=worker, gate=gate)
        self.first_on_node_close = advanced


class Queryable(Handle):
    """A served service; after `close()` callers get no reply from it.

    Requests already queued are still answered before the worker stops.
    """

    _drop_pending = False


class Token(Handle):
    """A liveliness token: the key is alive while the token is open."""


class Adopted(Handle):
    """A raw Zenoh entity handed to the node (benchmarks measuring bare Zenoh)."""


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


class Publisher(Handle, Generic[T]):
    """Puts messages of one catalogue topic on one concrete key.

    `entity`: a Zenoh publisher declared with the topic's encoding and QoS
    (an advanced one with a cache when the topic is latched).
    """

    def __init__(self, topic: keys.Topic, key: str, entity: Any,
                 on_close: Callable[[Handle], None]) -> None:
        super().__init__(key, entity, on_close)
        self.topic = topic
        self._z = entity
        self._encode = topic.codec.encode
        self._put = entity.put

    def put(self, msg: T) -> None:
        """Encode and put (the encoding was set once, at declaration)."""
        self._put(self._encode(msg))

    def put_bytes(self, payload: bytes) -> None:
        """Put an already encoded payload (for tools and tests)."""
        self._put(payload)

    def has_subscribers(self) -> bool:
        """Whether anyone listens (a latched publisher always answers True)."""
        if self.topic.latched:
            return True
        return _matching(self._z)


class RawPublisher(Handle):
    """Puts already encoded bytes on any concrete key (tools: `buddybot pub`).

    Congestion control DROP like every publisher of the robot; the encoding
    is set once at declaration.
    """

    def __init__(self, key: str, encoding: str, entity: Any,
                 on_close: Callable[[Handle], None]) -> None:
        super().__init__(key, entity, on_close)
        self.encoding = encoding
        self._z = entity
        self._put = entity.put

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        """Put `payload`; `attachment` travels with it (rmw_zenoh's sample metadata)."""
        if attachment is None:
            self._put(payload)
        else:
            self._put(payload, attachment=attachment)

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


class Worker:
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


def raw_reply(reply: zenoh.Reply) -> RawReply:
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


ZENOH_TIMEOUT = b"Timeout"  # a router's reply for a queryable that did not answer in time


def service_reply(replies: Iterator[RawReply], key: str, service: keys.Service,
                  timeout: float) -> ServiceReply:
    """The first reply decoded with the service's reply type, or the CallError;
    NoReplyError when nobody answered (a router's timeout reply included)."""
    for reply in replies:
        if not reply.ok and reply.payload == ZENOH_TIMEOUT:
            continue
        if not reply.ok:
            raise CallError(key, error_text(reply.payload))
        try:
            return ServiceReply(service.codec.decode(reply.payload, service.reply), reply.replier)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise CallError(key, f"malformed reply: {exc}") from None
    raise NoReplyError(key, f"no reply within {timeout:g} s (is the service running?)")


def error_payload(text: str) -> bytes:
    """The payload of an error reply saying `text` (read back by `error_text`)."""
    return msgspec.json.encode(m.ErrorReply(error=text))


def error_text(payload: bytes) -> str:
    """The text of an error reply (ours are ErrorReply JSON; others raw text)."""
    try:
        return msgspec.json.decode(payload, type=m.ErrorReply).error
    except (msgspec.DecodeError, msgspec.ValidationError):
        return payload.decode("utf-8", "replace")


class RawQuery:
    """One query to `Node.serve_raw`: its key, payload and attachment as sent.

    Replied to at most once (`reply`, `reply_err`); finished (the querier
    learns no more replies come) when the handler returns, unless it called
    `defer()`: then whoever replies later calls `finish()` (a ROS 2 action's
    result is asked for long before it exists). Thread-safe.
    """

    def __init__(self, query: zenoh.Query) -> None:
        self._query = query
        self.key = str(query.key_expr)
        payload, attachment = query.payload, query.attachment
        self.payload = b"" if payload is None else payload.to_bytes()
        self.attachment = None if attachment is None else attachment.to_bytes()
        self.deferred = False
        self._lock = threading.Lock()
        self._state: Literal["open", "replied", "finished"] = "open"

    def defer(self) -> None:
        self.deferred = True

    def reply(self, key: str, payload: bytes, *, encoding: str | None = None,
              attachment: bytes | None = None) -> bool:
        """Send the one reply; False (nothing sent) when it was sent or finished already."""
        with self._lock:
            if self._state != "open":
                return False
            self._state = "replied"
            extra: dict[str, Any] = {}
            if encoding is not None:
                extra["encoding"] = zenoh.Encoding(encoding)
            if attachment is not None:
                extra["attachment"] = attachment
            self._query.reply(key, payload, **extra)
            return True

    def reply_err(self, text: str) -> bool:
        """An error reply saying `text` (plain UTF-8: the querier may not be ours)."""
        with self._lock:
            if self._state != "open":
                return False
            self._state = "replied"
            self._query.reply_err(text.encode())
            return True

    def finish(self) -> None:
        """No more replies: the querier's get ends (idempotent)."""
        with self._lock:
            if self._state == "finished":
                return
            self._state = "finished"
            self._query.drop()
