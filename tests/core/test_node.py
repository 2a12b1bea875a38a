"""The node runtime through a real router: round trips, latching, bad input, liveliness."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, Router, free_port, retry_until

from .test_messages import sample_messages

pytestmark = pytest.mark.integration  # every test here talks through a real router

HERE = Path(__file__).parent


def _topic_for(msg: m.Message) -> keys.Topic | None:
    return next((t for t in keys.TOPICS if t.type is type(msg)), None)


def _params(topic: keys.Topic) -> dict[str, str]:
    return {p: "x1" for p in topic.params}


@pytest.mark.parametrize(
    "msg", [x for x in sample_messages() if _topic_for(x)], ids=lambda x: type(x).__name__
)
def test_round_trip_through_router(node_factory: Callable[..., Node], msg: m.Message) -> None:
    topic = _topic_for(msg)
    assert topic is not None
    if "stamp_ns" in type(msg).__struct_fields__:  # collected long ago: stamp it now
        msg = msgspec.structs.replace(msg, stamp_ns=m.now_ns())
    sender, receiver = node_factory("sender"), node_factory("receiver")
    got = Collector[m.Message](receiver, topic, **_params(topic))
    pub = sender.publisher(topic, **_params(topic))
    retry_until(lambda: pub.put(msg) or got.messages, 10, 0.2, "first delivery")
    assert got.messages[0] == msg


def test_late_joiner_gets_latched_value(node_factory: Callable[..., Node]) -> None:
    pub_node = node_factory("publisher")
    pub = pub_node.publisher(keys.EXPRESSION)
    first_stamp = m.now_ns()
    pub.put(m.ScreenExpression(stamp_ns=first_stamp, action=m.ExpressionAction.EYE_SLEEP))
    pub.put(m.ScreenExpression(stamp_ns=first_stamp + 1, action=m.ExpressionAction.EYE_AWAKE))
    late = node_factory("late")
    got = Collector[m.ScreenExpression](late, keys.EXPRESSION)
    first = got.wait_for(timeout=10, what="latched expression")
    assert first.action == m.ExpressionAction.EYE_AWAKE and first.stamp_ns == first_stamp + 1


def test_plain_topics_are_not_latched(node_factory: Callable[..., Node]) -> None:
    pub_node = node_factory("publisher")
    pub = pub_node.publisher(keys.PUPIL)
    old = m.now_ns()
    pub.put(m.PupilControl(stamp_ns=old, dilation_percentage=10))
    late = node_factory("late")
    got = Collector[m.PupilControl](late, keys.PUPIL)
    # Positive control: a new sample arrives, and it is the only one.
    retry_until(lambda: pub.put(m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=20))
                or got.messages, 10, 0.2)
    assert all(x.dilation_percentage == 20 and x.stamp_ns != old for x in got.messages)


def test_malformed_payloads_are_dropped_counted_and_survived(
    endpoint: str, log_dir: Path, node_factory: Callable[..., Node]
) -> None:
    proc = Process([sys.executable, str(HERE / "node_process.py"), endpoint, "victim"],
                   "victim", log_dir)
    try:
        proc.wait_for_output("READY", 30)
        probe = node_factory("probe")
        diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="victim")
        garbage = [b"", b"\xff\x00garbage", b"{}", b'{"stamp_ns": -5}', b"[1,2,3]" * 1000]
        for topic in keys.TOPICS:
            key = probe.key(topic, **_params(topic))
            for payload in garbage:  # BLOCK: none lost on the way, so the count is exact
                # (the raw session on purpose: no publisher of the node may BLOCK)
                probe._session.put(key, payload,
                                   congestion_control=zenoh.CongestionControl.BLOCK)
        # Still alive and still working: a valid message is received after the garbage.
        good = probe.publisher(keys.PUPIL)
        retry_until(lambda: good.put(m.PupilControl(stamp_ns=1, dilation_percentage=5))
                    or int(diag.messages[-1].values.get("received", 0)) > 0 if diag.messages
                    else False, 20, 0.2, "valid message after garbage")
        status = diag.wait_for(
            lambda s: int(s.values.get("malformed", 0)) >= len(keys.TOPICS) * len(garbage) - 1,
            timeout=20, what="malformed count")
        assert proc.alive()
        assert int(status.values["malformed"]) <= len(keys.TOPICS) * len(garbage)
        out = proc.output()
        # Rate-limited: far fewer warning lines than malformed samples.
        assert 0 < out.count("dropped malformed") <= len(keys.TOPICS) + 2
    finally:
        proc.stop()


def test_liveliness_token_disappears_when_process_is_killed(
    endpoint: str, log_dir: Path, node_factory: Callable[..., Node]
) -> None:
    probe = node_factory("probe")
    proc = Process([sys.executable, str(HERE / "node_process.py"), endpoint, "doomed"],
                   "doomed", log_dir)
    try:
        proc.wait_for_output("READY", 30)
        retry_until(lambda: "doomed" in probe.node_instances(), 10)
        proc.kill()
        retry_until(lambda: "doomed" not in probe.node_instances(), 10,
                    what="token gone")
    finally:
        proc.stop()


def test_node_waits_for_a_router_that_is_not_up_yet(log_dir: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    proc = Process([sys.executable, str(HERE / "node_process.py"), endpoint, "early"],
                   "early", log_dir)
    router = None
    try:
        proc.wait_for_output("waiting for the Zenoh router", 30)
        assert proc.alive() and "READY" not in proc.output()
        router = Router(port, log_dir)
        proc.wait_for_output("READY", 30)
        probe = Node("probe", connect=[endpoint])
        try:
            retry_until(lambda: "early" in probe.node_instances(), 10)
        finally:
            probe.close()
    finally:
        proc.stop()
        if router:
            router.stop()


def test_router_restart_is_survived(log_dir: Path) -> None:
    router = Router(log_dir=log_dir)
    port = router.port
    sender = Node("sender", connect=[router.endpoint])
    receiver = Node("receiver", connect=[router.endpoint])
    try:
        got = Collector[m.PupilControl](receiver, keys.PUPIL)
        pub = sender.publisher(keys.PUPIL)
        retry_until(lambda: pub.put(m.PupilControl(stamp_ns=1, dilation_percentage=1))
                    or got.messages, 10, 0.2)
        router.kill()
        router = Router(port, log_dir)
        got.clear()
        retry_until(lambda: pub.put(m.PupilControl(stamp_ns=2, dilation_percentage=2))
                    or got.messages, 15, 0.2, "traffic after router restart")
    finally:
        receiver.close()
        sender.close()
        router.stop()


def test_two_robots_do_not_cross_talk(node_factory: Callable[..., Node]) -> None:
    a_pub = node_factory("a", robot="alpha").publisher(keys.PUPIL)
    b_node = node_factory("b", robot="beta")
    b_got = Collector[m.PupilControl](b_node, keys.PUPIL)
    b_pub = node_factory("b2", robot="beta").publisher(keys.PUPIL)
    for _ in range(5):
        a_pub.put(m.PupilControl(stamp_ns=1, dilation_percentage=1))
    retry_until(lambda: b_pub.put(m.PupilControl(stamp_ns=2, dilation_percentage=2))
                or b_got.messages, 10, 0.2)
    assert {x.dilation_percentage for x in b_got.messages} == {2}


def test_service_call_replies_and_errors(node_factory: Callable[..., Node]) -> None:
    server, client = node_factory("server"), node_factory("client")
    calls: list[m.PlayAudioFile] = []

    def play(req: m.PlayAudioFile) -> m.TriggerReply:
        if req.path == "boom":
            raise RuntimeError("exploded")
        calls.append(req)
        return m.TriggerReply(success=True, message=f"playing {req.path}")

    server.serve(keys.PLAY_FILE, play)
    reply = retry_until(lambda: client.call(keys.PLAY_FILE, m.PlayAudioFile(path="a.wav"),
                                            timeout=2), 15, 0.2)
    assert reply == m.TriggerReply(success=True, message="playing a.wav")
    with pytest.raises(ServiceError, match="exploded"):
        client.call(keys.PLAY_FILE, m.PlayAudioFile(path="boom"))
    # A malformed request gets an error reply naming the problem, not silence.
    replies = list(client.query(client.key(keys.PLAY_FILE), b'{"pth": 1}', timeout=5))
    assert replies and not replies[0].ok
    assert "pth" in replies[0].payload.decode()
    assert msgspec.json.decode(replies[0].payload)["error"]
    with pytest.raises(ServiceError, match="no reply"):
        client.call(keys.AUDIO_PAUSE, m.Trigger(), timeout=0.5)
    assert {c.path for c in calls} == {"a.wav"}  # retries may repeat it; "boom" never lands


def test_latest_delivery_keeps_the_newest_and_reports_what_it_dropped(
    node_factory: Callable[..., Node]
) -> None:
    """A slow handler on `latest` sees the newest sample, never a backlog; the samples it
    skipped are counted in diagnostics."""
    sender, slow = node_factory("sender"), node_factory("slow", diagnostics_period_s=0.2)
    release, seen = threading.Event(), []

    def handler(msg: m.PupilControl, _key: str) -> None:
        seen.append(int(msg.dilation_percentage))
        release.wait(10)

    slow.subscribe(keys.PUPIL, handler, delivery="latest")
    diag = Collector[m.DiagnosticStatus](node_factory("watcher"), keys.DIAGNOSTICS, node="slow")
    pub = sender.publisher(keys.PUPIL)
    retry_until(lambda: pub.put(m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=1))
                or seen, 10, 0.1, "handler busy with the first sample")
    for marker in range(2, 52):  # the handler is stuck: these pile onto the latest slot
        pub.put(m.PupilControl(stamp_ns=m.now_ns(), dilation_percentage=marker))
    status = diag.wait_for(lambda s: int(s.values.get("dropped eyes/pupil", 0)) >= 40, 20,
                           what="dropped count in diagnostics")
    release.set()
    retry_until(lambda: seen[-1] == 51, 10, 0.05, "the newest sample handled next")
    assert len(seen) <= 3 and int(status.values["dropped eyes/pupil"]) <= 50
