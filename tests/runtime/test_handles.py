"""Handles: every declaration of a node can be closed on its own, through a real router.

Why: services and tools must stop one subscription, one service or one
token without closing the node and without a raw Zenoh session.
Each test checks the effect on the bus (deliveries, replies, liveliness),
not only a flag, so a `close()` that forgets to undeclare fails it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.node import Node, NoReplyError, ServiceReply
from buddybot.tools.testing import Collector, retry_until

pytestmark = pytest.mark.integration  # every test here talks through a real router


def _pupil(value: int) -> m.PupilControl:
    return m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=value)


class _Seen:
    """Dilation values a subscription delivered, with an event per value."""

    def __init__(self) -> None:
        self.values: list[int] = []
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)

    def __call__(self, msg: m.PupilControl, _key: str) -> None:
        with self._changed:
            self.values.append(int(msg.dilation_percentage))
            self._changed.notify_all()

    def wait_for(self, value: int, timeout: float = 10.0) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: value in self.values, timeout)


def _no_reply(client: Node, service: keys.Service, request: m.Message) -> bool:
    """True once a call gets no reply at all (the queryable is gone)."""
    try:
        client.call(service, request, timeout=0.5)
    except NoReplyError:
        return True
    return False


@pytest.mark.parametrize("delivery", ["inline", "queue"])
def test_closing_a_subscription_stops_it_and_only_it(
    node_factory: Callable[..., Node], delivery: str
) -> None:
    sender, receiver = node_factory("sender"), node_factory("receiver")
    closed_seen, kept_seen = _Seen(), _Seen()
    doomed = receiver.subscribe(keys.PUPIL, closed_seen, delivery=delivery)  # type: ignore[arg-type]
    kept = receiver.subscribe(keys.PUPIL, kept_seen)
    pub = sender.publisher(keys.PUPIL)
    retry_until(lambda: pub.put(_pupil(1)) or (closed_seen.values and kept_seen.values),
                10, 0.1, "both subscriptions receive")

    doomed.close()
    assert doomed.closed and doomed not in receiver.handles and kept in receiver.handles
    before = len(closed_seen.values)
    for value in range(2, 12):
        pub.put(_pupil(value))
    assert kept_seen.wait_for(11), "the other subscription on the same key stopped too"
    assert len(closed_seen.values) == before, "a closed subscription still delivers"
    if delivery == "queue":
        worker = doomed.worker
        assert worker is not None and not worker._thread.is_alive()


def test_closing_a_queryable_makes_calls_get_no_reply(node_factory: Callable[..., Node]) -> None:
    server, client = node_factory("server"), node_factory("client")
    stop = server.serve(keys.AUDIO_STOP, lambda _r: m.TriggerReply(success=True, message="stop"))
    pause = server.serve(keys.AUDIO_PAUSE, lambda _r: m.TriggerReply(success=True, message="p"))
    retry_until(lambda: client.call(keys.AUDIO_STOP, m.Trigger(), timeout=2), 15, 0.2)

    stop.close()
    retry_until(lambda: _no_reply(client, keys.AUDIO_STOP, m.Trigger()), 10, 0.1,
                "no reply after close")
    with pytest.raises(ServiceError, match="no reply"):
        client.call(keys.AUDIO_STOP, m.Trigger(), timeout=0.5)
    # The node and its other service keep running.
    assert client.call(keys.AUDIO_PAUSE, m.Trigger(), timeout=5).message == "p"
    assert pause in server.handles and stop not in server.handles


def test_close_twice_and_context_managers(node_factory: Callable[..., Node]) -> None:
    node, watcher = node_factory("owner"), node_factory("watcher")
    key = node.key(keys.NODES, node="borrowed", instance="abc123")
    with node.declare_token(key) as token:
        retry_until(lambda: watcher.live_instances(key, timeout=1.0) == {"abc123"}, 10, 0.1,
                    "token seen")
    assert token.closed and token not in node.handles
    retry_until(lambda: not watcher.live_instances(key, timeout=1.0), 10, 0.1, "token gone")
    token.close()  # again: harmless

    got = _Seen()
    with node.subscribe(keys.PUPIL, got) as sub:
        pass
    sub.close()
    sub.close()
    assert sub.closed and sub not in node.handles
    with node.publisher(keys.PUPIL) as pub:
        assert not pub.closed
    assert pub.closed
    pub.close()


def test_a_probe_is_not_a_node(node_factory: Callable[..., Node]) -> None:
    ghost = node_factory("ghost", probe=True)
    visible = node_factory("visible")
    assert ghost.handles == []  # no token, no node watch, no diagnostics publisher
    # Positive control: the listing works, from the probe itself too.
    found = retry_until(lambda: ghost.node_instances(timeout=1.0).get("visible"), 10, 0.1)
    assert found == {visible.instance}
    listed = retry_until(lambda: (seen := visible.node_instances(timeout=1.0)) and
                         "visible" in seen and seen, 10, 0.1)
    assert "ghost" not in listed
    assert "buddy/visible" in ghost.node_instances(all_robots=True, timeout=1.0)
    # It still works as a client: a service call from a probe is answered.
    visible.serve(keys.AUDIO_STOP, lambda _r: m.TriggerReply(success=True))
    assert retry_until(lambda: ghost.call(keys.AUDIO_STOP, m.Trigger(), timeout=2), 15, 0.2)
    with pytest.raises(ValueError, match="probe"):
        Node("both", probe=True, unique=True)


def test_call_names_the_instance_that_replied(node_factory: Callable[..., Node]) -> None:
    server, client = node_factory("server"), node_factory("client", probe=True)
    server.serve(keys.AUDIO_STOP, lambda _r: m.TriggerReply(success=True, message="ok"))
    reply = retry_until(lambda: client.call(keys.AUDIO_STOP, m.Trigger(), timeout=2,
                                            with_replier=True), 15, 0.2)
    assert isinstance(reply, ServiceReply)
    assert reply.value == m.TriggerReply(success=True, message="ok")
    assert reply.replier == server.instance != client.instance
    by_key = client.call_key(server.key(keys.AUDIO_STOP), keys.AUDIO_STOP, m.Trigger(),
                             timeout=5, with_replier=True)
    assert by_key.replier == server.instance
    assert client.call_key(server.key(keys.AUDIO_STOP), keys.AUDIO_STOP, m.Trigger()) \
        == reply.value


def test_raw_side_for_tools(node_factory: Callable[..., Node]) -> None:
    """Raw bytes on any key, with wildcards and latched history, as echo/pub need."""
    service = node_factory("face-service")
    latched = service.publisher(keys.EXPRESSION)
    latched.put(m.ScreenExpression(stamp_ns=m.now_ns(), action=m.ExpressionAction.EYE_AWAKE))
    tool = node_factory("echo", probe=True)
    got: list[tuple[str, bytes, str]] = []
    arrived = threading.Event()

    def on_raw(key: str, payload: bytes, encoding: str) -> None:
        got.append((key, payload, encoding))
        arrived.set()

    # Late joiner with history: the latched value arrives without a new put.
    with tool.subscribe_raw(f"{tool.prefix}/*/expression", on_raw, history=True):
        assert arrived.wait(10), "latched value not delivered"
    key, payload, encoding = got[0]
    assert key == service.key(keys.EXPRESSION) and encoding == keys.EXPRESSION.encoding
    assert keys.EXPRESSION.codec.decode(payload, m.ScreenExpression).action \
        == m.ExpressionAction.EYE_AWAKE

    # A raw publisher knows whether anyone listens, before and after.
    listener = node_factory("listener")
    heard = _Seen()
    out = tool.raw_publisher(tool.key(keys.PUPIL), keys.PUPIL.encoding)
    assert not out.has_subscribers()
    sub = listener.subscribe(keys.PUPIL, heard)
    assert out.wait_for_subscribers(10)
    out.put(keys.PUPIL.codec.encode(_pupil(42)))
    assert heard.wait_for(42)
    sub.close()
    retry_until(lambda: not out.has_subscribers(), 10, 0.05, "no subscriber after close")
    with pytest.raises(ValueError, match="wildcard"):
        tool.raw_publisher(f"{tool.prefix}/*", "application/json")


def test_node_close_after_some_handles_were_closed(node_factory: Callable[..., Node],
                                                   endpoint: str) -> None:
    watcher = node_factory("watcher")
    node = Node("closing", connect=[endpoint])
    subs = [node.subscribe(keys.PUPIL, _Seen(), delivery="queue") for _ in range(3)]
    served = node.serve(keys.AUDIO_STOP, lambda _r: m.TriggerReply(success=True))
    raw = node.subscribe_raw(node.key(keys.LIDS), lambda *_a: None, history=True)
    subs[0].close()
    served.close()
    retry_until(lambda: "closing" in watcher.node_instances(timeout=1.0), 10, 0.1)
    node.close()
    assert node.handles == [] and not node.connected()
    assert all(s.closed for s in [*subs, served, raw])
    raw.close()  # after the node: harmless
    node.close()
    retry_until(lambda: "closing" not in watcher.node_instances(timeout=1.0), 10, 0.1,
                "token gone with the node")


def test_connected_follows_the_node(node_factory: Callable[..., Node]) -> None:
    node = node_factory("on-bus")
    assert retry_until(node.connected, 10, 0.05)
    diag = Collector[m.DiagnosticStatus](node_factory("watcher"), keys.DIAGNOSTICS,
                                         node="on-bus")
    diag.wait_for(timeout=10, what="a normal node publishes diagnostics")
    node.close()
    assert not node.connected()
