"""`buddybot run ros2-bridge` (services/ros2/service.py) as a real process on a real
router, met by a peer that is not ours: a raw Zenoh session (no BuddyBot
runtime) reading and writing rmw_zenoh's key expressions, with
mcap-ros2-support's CDR decoder and encoder (tests/ros2/test_convert.py).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, types, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.node import Node, zenoh_config
from buddybot.tools.testing import Collector, Process, retry_until

from .test_convert import DEPENDENCIES, STANDARD, schema_of_ours, their_decoder, their_encoder

SETTINGS = Ros2Settings(domain_id=3)
FACE = bridge.route(SETTINGS, "face_position", types.POINT_STAMPED)
EXPRESSION = bridge.route(SETTINGS, "screen_expression", bridge.EXPRESSION)


@pytest.fixture
def peer(endpoint: str) -> Iterator[zenoh.Session]:
    """A plain Zenoh session on the test router: no BuddyBot node, no tokens."""
    session = zenoh.open(zenoh_config(connect=[endpoint]))
    yield session
    session.close()


def graph(peer: zenoh.Session) -> list[wire.GraphToken]:
    """The bridge's graph tokens, as a ROS 2 peer's liveliness query sees them."""
    found = []
    for reply in peer.liveliness().get(f"{wire.PREFIX}/{SETTINGS.domain_id}/**", timeout=2.0):
        if reply.ok is not None:
            found.append(wire.GraphToken.parse(str(reply.ok.key_expr)))
    return found


def counter(diag: Collector[m.DiagnosticStatus], name: str) -> int:
    messages = diag.messages
    return int(messages[-1].values.get(name, 0)) if messages else 0


@pytest.fixture
def started(spawn: Callable[..., Process], peer: zenoh.Session) -> list[wire.GraphToken]:
    spawn("ros2-bridge", "--domain-id", str(SETTINGS.domain_id))

    def complete() -> list[wire.GraphToken] | None:
        tokens = graph(peer)  # the subscription's token is declared last
        return tokens if any(t.kind == "MS" for t in tokens) else None

    return retry_until(complete, 30, 0.2, "the bridge's graph tokens")


@pytest.mark.integration
def test_the_graph_and_a_face_as_a_ros_2_peer_sees_them(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node) -> None:
    kinds = sorted((t.kind, t.name or "") for t in started  # services: test_servers.py
                   if t.kind != "SS" and "/_action/" not in (t.name or ""))
    assert kinds == [("MP", "/audio_device_is_free"), ("MP", "/face_position"),
                     ("MP", "/radar_presence"), ("MP", "/screen_expression"),
                     ("MS", "/screen_expression"), ("NN", "")]
    assert {t.node_name for t in started} == {bridge.NODE_NAME}
    assert len({t.session_id for t in started}) == 1
    face_token = next(t for t in started if t.name == "/face_position")
    assert (face_token.type_name, face_token.type_hash) == (
        "geometry_msgs::msg::dds_::PointStamped_", FACE.type_hash)

    got: list[tuple[bytes, bytes | None]] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        att = sample.attachment
        got.append((sample.payload.to_bytes(), None if att is None else att.to_bytes()))
        arrived.set()

    peer.declare_subscriber(FACE.key, on_sample)
    publisher = probe.publisher(keys.FACE, camera="front")
    stamp = m.now_ns()
    face = m.FacePosition(stamp_ns=stamp, frame_id="camera_link",
                          point=m.Point(x=0.8, y=-0.1, z=0.05), confidence=0.9)

    def sent() -> bool:
        publisher.put(face)
        return arrived.wait(0.2)

    retry_until(sent, 30, 0.0, "/face_position at the raw peer")
    payload, attachment = got[0]
    decoded = their_decoder(types.POINT_STAMPED,
                            STANDARD[types.POINT_STAMPED] + DEPENDENCIES)(payload)
    assert decoded.header.frame_id == "camera_link"
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == divmod(stamp, 10**9)
    assert (decoded.point.x, decoded.point.y, decoded.point.z) == (0.8, -0.1, 0.05)
    assert attachment is not None
    first = wire.Attachment.decode(attachment)
    assert first.sequence >= 1 and first.timestamp_ns > 0
    if len(got) > 1:
        later = wire.Attachment.decode(got[-1][1] or b"")
        assert later.gid == first.gid and later.sequence > first.sequence


@pytest.mark.integration
def test_a_ros_2_expression_reaches_the_eyes_and_garbage_is_counted(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node,
        spawn: Callable[..., Process]) -> None:
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="ros2-bridge")
    spawn("controller")
    expressions.wait_for(timeout=30, what="the controller's own expression")
    retry_until(lambda: any(i.node == "controller" and "eyes/command" in i.services
                            for i in probe.node_infos(1.0)),
                30, 0.2, "the controller's lease services")

    encode: Any = their_encoder(bridge.EXPRESSION, schema_of_ours("ScreenExpression"))
    grin = encode({"stamp_ns": 5, "action": int(m.ExpressionAction.EYE_GRIN)})
    gid = bytes(range(16))

    def put(key: str, payload: bytes, sequence: int = 1) -> None:
        peer.put(key, payload, attachment=wire.Attachment(sequence, m.now_ns(), gid).encode())

    put(EXPRESSION.key, b"\x00\x01\x00\x00garbage")
    retry_until(lambda: counter(diag, "malformed") >= 1, 30, 0.2, "the garbage counted")
    wrong = EXPRESSION.key.rsplit("/", 1)[0] + "/RIHS01_" + "0" * 64
    put(wrong, grin)
    retry_until(lambda: counter(diag, "wrong_type") >= 1, 30, 0.2, "the wrong hash counted")

    put(EXPRESSION.key, grin, 2)
    expressions.wait_for(lambda e: e.action == m.ExpressionAction.EYE_GRIN, 30,
                         "EYE_GRIN from the ROS 2 peer")
    retry_until(lambda: counter(diag, "commands") >= 1, 30, 0.2, "the command counted")
    assert counter(diag, "malformed") == 1 and counter(diag, "wrong_type") == 1
