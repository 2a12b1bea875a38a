"""The node runtime through a real router: round trips, latching, bad input, liveliness,
and its guards: no sample can freeze or bloat a handler, every query is answered, one name
is one process."""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import DuplicateNodeError, ServiceError
from buddybot.runtime.handles import RawQuery
from buddybot.runtime.node import Node, RawReply, zenoh_config
from buddybot.tools.testing import (
    Collector,
    Process,
    Router,
    buddybot_argv,
    free_port,
    retry_until,
)
from tests.contract.test_messages import sample_messages

pytestmark = pytest.mark.integration  # every test here talks through a real router

HERE = Path(__file__).parent
S = 1_000_000_000


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


def _pupil(stamp: int, marker: float) -> m.PupilControl:
    return m.PupilControl(stamp_ns=stamp, dilation_percentage=marker)


def test_implausible_stamps_are_replaced_and_never_freeze_ordering(
    node_factory: Callable[..., Node]
) -> None:
    """A stamp from the far future (or the past) reaches the handler as its arrival
    time, so a "newest stamp wins" consumer keeps taking later samples."""
    sender = node_factory("sender")
    receiver = node_factory("receiver", diagnostics_period_s=0.2)
    got = Collector[m.PupilControl](receiver, keys.PUPIL)
    diag = Collector[m.DiagnosticStatus](node_factory("watcher"), keys.DIAGNOSTICS,
                                         node="receiver")
    pub = sender.publisher(keys.PUPIL)
    retry_until(lambda: pub.put(_pupil(m.now_ns(), 1)) or got.messages, 10, 0.1, "delivery")
    for stamp, marker in ((2**63 - 1, 2), (m.now_ns() + 15 * S, 3), (m.now_ns() - 60 * S, 4)):
        before = m.now_ns()
        pub.put(_pupil(stamp, marker))
        msg = got.wait_for(lambda x, marker=marker: x.dilation_percentage == marker, 10)
        assert before <= msg.stamp_ns <= m.now_ns(), (stamp, msg.stamp_ns)
    fine = m.now_ns()
    pub.put(_pupil(fine, 5))
    assert got.wait_for(lambda x: x.dilation_percentage == 5, 10).stamp_ns == fine
    status = diag.wait_for(lambda s: s.values.get("stamps replaced") == 3, 10,
                           what="3 replaced stamps counted")
    assert status.values.get("malformed", 0) == 0


def test_a_latched_value_keeps_its_old_stamp_but_not_a_future_one(
    node_factory: Callable[..., Node]
) -> None:
    pub = node_factory("sender").publisher(keys.EXPRESSION)
    old = m.now_ns() - 3600 * S
    pub.put(m.ScreenExpression(stamp_ns=old, action=m.ExpressionAction.EYE_SLEEP))
    late = Collector[m.ScreenExpression](node_factory("late"), keys.EXPRESSION)
    assert late.wait_for(timeout=10).stamp_ns == old
    pub.put(m.ScreenExpression(stamp_ns=2**63 - 1, action=m.ExpressionAction.EYE_AWAKE))
    awake = late.wait_for(lambda e: e.action == m.ExpressionAction.EYE_AWAKE, 10)
    assert awake.stamp_ns <= m.now_ns()


def test_oversized_samples_are_dropped_unread(node_factory: Callable[..., Node]) -> None:
    receiver = node_factory("receiver", diagnostics_period_s=0.2)
    got = Collector[m.PupilControl](receiver, keys.PUPIL)
    diag = Collector[m.DiagnosticStatus](node_factory("watcher"), keys.DIAGNOSTICS,
                                         node="receiver")
    probe = node_factory("probe")
    key = probe.key(keys.PUPIL)
    # Valid JSON, padded past the 64 KiB bound of a small key.
    big = b'{"stamp_ns": %d, "dilation_percentage": 7}' % m.now_ns() + b" " * 70_000
    small = keys.PUPIL.codec.encode(_pupil(m.now_ns(), 8))
    raw = probe.raw_publisher(key, keys.PUPIL.encoding)
    retry_until(lambda: raw.put(big) or raw.put(small) or got.messages, 10, 0.1,
                "the small sample")
    assert all(x.dilation_percentage == 8 for x in got.messages)
    diag.wait_for(lambda s: int(s.values.get("oversized", 0)) >= 1, 10, what="oversized count")


def test_every_query_is_answered_even_when_the_handler_is_swamped(
    node_factory: Callable[..., Node]
) -> None:
    """200 concurrent requests to a handler with a queue of 4: each gets exactly one
    reply (served, or refused as busy at once); none is left without an answer."""
    server = node_factory("server")
    release = threading.Event()

    def slow(_req: m.Trigger) -> m.TriggerReply:
        release.wait(5)
        return m.TriggerReply(success=True)

    server.serve(keys.AUDIO_STOP, slow, queue_size=4)
    client = node_factory("client")
    key = client.key(keys.AUDIO_STOP)
    retry_until(lambda: client.live_instances(client.key(keys.NODES, node="server")), 10)
    answers: list[list[RawReply]] = []
    lock = threading.Lock()

    def ask() -> None:
        replies = list(client.query(key, b"{}", timeout=30))
        with lock:
            answers.append(replies)

    threads = [threading.Thread(target=ask) for _ in range(200)]
    for thread in threads:
        thread.start()
    retry_until(lambda: sum(1 for a in answers if a and not a[0].ok) >= 150, 30, 0.05,
                "most requests refused as busy while the handler is stuck")
    release.set()
    for thread in threads:
        thread.join(60)
    assert len(answers) == 200
    assert all(len(a) == 1 for a in answers), "a request got no reply (or several)"
    served = [a[0] for a in answers if a[0].ok]
    busy = [a[0] for a in answers if not a[0].ok]
    assert served and busy
    assert all(b"busy" in r.payload for r in busy)


def test_a_too_large_request_is_refused_unread(node_factory: Callable[..., Node]) -> None:
    server = node_factory("server")
    calls: list[m.PlayAudioFile] = []
    server.serve(keys.PLAY_FILE, lambda req: calls.append(req) or m.TriggerReply(success=True))
    client = node_factory("client")
    retry_until(lambda: client.call(keys.PLAY_FILE, m.PlayAudioFile(path="ok"), timeout=5), 15,
                0.2, "the service discovered")
    with pytest.raises(ServiceError, match="too large"):
        client.call(keys.PLAY_FILE, m.PlayAudioFile(path="x" * 100_000), timeout=10)
    assert [c.path for c in calls] == ["ok"] * len(calls)


def test_a_second_instance_of_a_unique_node_is_refused(
    node_factory: Callable[..., Node], endpoint: str
) -> None:
    first = node_factory("controller", unique=True)
    with pytest.raises(DuplicateNodeError, match=first.instance):
        Node("controller", connect=[endpoint], unique=True)
    # Not unique (tools, tests): allowed, and then both sides see two instances.
    seen: list[frozenset[str]] = []
    first.watch_node("controller", seen.append)
    second = node_factory("controller")
    retry_until(lambda: seen and seen[-1] == {first.instance, second.instance}, 10, 0.05,
                "both instances watched")
    second.close()
    retry_until(lambda: seen[-1] == {first.instance}, 10, 0.05, "the second one gone")


def test_a_duplicate_is_reported_by_its_diagnostics_and_by_nodes(
    node_factory: Callable[..., Node], endpoint: str
) -> None:
    first = node_factory("audio-player", diagnostics_period_s=0.2)
    diag = Collector[m.DiagnosticStatus](node_factory("watcher"), keys.DIAGNOSTICS,
                                         node="audio-player")
    # A fake token from another session, as an attacker would declare it.
    fake_key = first.key(keys.NODES, node="audio-player", instance="f00d")
    token = node_factory("attacker").declare_token(fake_key)
    try:
        diag.wait_for(lambda s: s.level == "WARN" and "f00d" in s.message, 10,
                      what="duplicate warning")
        out = retry_until(lambda: _nodes_output(endpoint), 20, 0.2)
        assert "audio-player  DUPLICATE: 2 instances" in out and "f00d" in out
    finally:
        token.close()
    diag.wait_for(lambda s: s.level == "OK", 10, what="duplicate warning cleared")


def _nodes_output(endpoint: str) -> str:
    out = subprocess.run(buddybot_argv("nodes", "--connect", endpoint), capture_output=True,
                         text=True, timeout=60, check=False).stdout
    return out if "DUPLICATE" in out else ""


def test_a_duplicate_service_process_exits_2_naming_the_other(
    node_factory: Callable[..., Node], endpoint: str
) -> None:
    node_factory("controller")
    done = subprocess.run(
        buddybot_argv("run", "controller", "--connect", endpoint),
        capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 2, done.stderr[-2000:]
    assert "another controller is already running" in done.stderr


def test_encoded_values_are_bounded(node_factory: Callable[..., Node]) -> None:
    """A face 1e200 m away is refused at decode, never a `null` distance on the wire."""
    receiver = node_factory("receiver")
    got = Collector[m.FacePosition](receiver, keys.FACE, camera="front")
    probe = node_factory("probe")
    key = probe.key(keys.FACE, camera="front")
    far = (b'{"stamp_ns": %d, "frame_id": "f", "point": {"x": 1e200, "y": 0, "z": 0}, '
           b'"confidence": 0.5}' % m.now_ns())
    ok = msgspec.json.encode(m.FacePosition(stamp_ns=m.now_ns(), frame_id="ok",
                                            point=m.Point(x=1.0, y=0, z=0), confidence=0.5))
    raw = probe.raw_publisher(key, keys.FACE.encoding)
    retry_until(lambda: raw.put(far) or raw.put(ok) or got.messages, 10, 0.1)
    assert {x.frame_id for x in got.messages} == {"ok"}


def test_a_raw_queryable_replies_later_or_never_and_survives_its_handler(
    node_factory: Callable[..., Node], endpoint: str, request: pytest.FixtureRequest
) -> None:
    """`serve_raw`: payload and attachment as sent; a deferred query is answered by
    another thread; a handler that replies nothing, or fails, still ends the query."""
    server = node_factory("server")
    held: list[RawQuery] = []
    got: list[tuple[str, bytes, bytes | None]] = []

    def handler(query: RawQuery) -> None:
        got.append((query.key, query.payload, query.attachment))
        if query.payload == b"later":
            query.defer()
            held.append(query)
        elif query.payload == b"boom":
            raise RuntimeError("boom")
        elif query.payload == b"echo":
            query.reply(query.key, b"echo!", attachment=b"att")

    server.serve_raw("raw/test/*", handler, complete=True)
    client = node_factory("client", probe=True)
    retry_until(lambda: client.live_instances(client.key(keys.NODES, node="server")), 10)
    session = zenoh.open(zenoh_config(connect=[endpoint]))  # a querier that is not a node
    request.addfinalizer(session.close)
    replies = list(session.get("raw/test/a", payload=b"echo", attachment=b"in", timeout=10,
                               target=zenoh.QueryTarget.ALL_COMPLETE))
    assert [(r.ok.payload.to_bytes(), r.ok.attachment.to_bytes()) for r in replies
            if r.ok is not None] == [(b"echo!", b"att")]
    assert got[0] == ("raw/test/a", b"echo", b"in")
    assert list(session.get("raw/test/b", payload=b"silent", timeout=10)) == []
    assert list(session.get("raw/test/b", payload=b"boom", timeout=10)) == []

    def answer_later() -> None:
        retry_until(lambda: held, 10, 0.01, "the deferred query")
        held[0].reply(held[0].key, b"late")
        held[0].finish()

    thread = threading.Thread(target=answer_later)
    thread.start()
    late = list(session.get("raw/test/c", payload=b"later", timeout=10))
    thread.join(10)
    assert [r.ok.payload.to_bytes() for r in late if r.ok is not None] == [b"late"]
    assert held[0].reply("raw/test/c", b"again") is False  # once only
