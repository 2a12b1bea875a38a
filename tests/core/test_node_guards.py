"""The runtime's guards through a real router (issue 11): no sample can freeze or
bloat a handler, every query is answered, one name is one process."""

from __future__ import annotations

import subprocess
import threading
from collections.abc import Callable

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import DuplicateNodeError, ServiceError
from buddybot.runtime.node import Node, RawReply
from buddybot.tools.testing import Collector, buddybot_argv, retry_until

pytestmark = pytest.mark.integration  # every test here talks through a real router

S = 1_000_000_000


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
    """A face 1e200 m away is refused at decode (it used to become a `null` distance)."""
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
