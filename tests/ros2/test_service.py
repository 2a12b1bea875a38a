"""`buddybot run ros2-bridge` (services/ros2/service.py) as a real process on a real
router, met by a peer that is not ours: a raw Zenoh session (no BuddyBot
runtime) reading and writing rmw_zenoh's key expressions, with
mcap-ros2-support's CDR decoder and encoder (tests/ros2/test_convert.py).
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, hri, rosbag, service, types, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.node import Node, zenoh_config
from buddybot.tools.testing import Collector, Process, retry_until

from .test_convert import (
    DEPENDENCIES,
    POSES,
    STANDARD,
    schema_of_ours,
    their_decoder,
    their_encoder,
)

SETTINGS = Ros2Settings(domain_id=3)
FACE = bridge.route(SETTINGS, "face_position", types.POINT_STAMPED)
EXPRESSION = bridge.route(SETTINGS, "screen_expression", bridge.EXPRESSION)
EYE_CONTROL = bridge.route(SETTINGS, "eye_control", bridge.EYE_CONTROL)
RAW_IMAGE = bridge.route(SETTINGS, "raw_image", types.IMAGE)
LIDS = bridge.route(SETTINGS, "eye_lid_control", f"{types.OURS}/msg/EyeLidControl")
TARGETS = bridge.route(SETTINGS, "ld2450_targets", types.POSE_ARRAY)


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


TOPIC_TOKENS = frozenset({("NN", ""), ("MS", "/screen_expression"), ("MS", "/eye_control"),
                          *(("MP", f"/{o.name}") for o in bridge.OUTGOING),
                          *(("MP", f"/{name}") for name in hri.STATIC_TOPICS)})
"""The bridge's node and topic tokens as a ROS 2 peer sees them (services apart)."""


@pytest.fixture
def started(spawn: Callable[..., Process], peer: zenoh.Session) -> list[wire.GraphToken]:
    spawn("ros2-bridge", "--domain-id", str(SETTINGS.domain_id))

    def complete() -> list[wire.GraphToken] | None:
        tokens = graph(peer)  # every topic's, whatever order they are declared in
        return tokens if {(t.kind, t.name or "") for t in tokens} >= TOPIC_TOKENS else None

    return retry_until(complete, 30, 0.2, "the bridge's graph tokens")


@pytest.fixture
def diag(probe: Node) -> Collector[m.DiagnosticStatus]:
    """The bridge's diagnostics (its counters)."""
    return Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="ros2-bridge")


@pytest.fixture
def controller(spawn: Callable[..., Process], probe: Node) -> Process:
    """The eyes driver and the controller, once the arbiter's lease services (the
    bridge's commands) are declared; the controller's process."""
    spawn("eyes")
    retry_until(lambda: any(i.node == "eyes" and "eyes/command" in i.services
                            for i in probe.node_infos(1.0)),
                30, 0.2, "the arbiter's lease services")
    return spawn("controller")


@pytest.mark.integration
def test_the_graph_and_a_face_as_a_ros_2_peer_sees_them(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node) -> None:
    kinds = sorted((t.kind, t.name or "") for t in started  # services: test_servers.py
                   if t.kind != "SS" and "/_action/" not in (t.name or ""))
    assert kinds == sorted(TOPIC_TOKENS)  # each once
    qos = {(t.kind, t.name): t.qos for t in started}
    assert qos["MP", "/eye_lid_control"] == bridge.LATCHED_QOS
    assert qos["MP", "/raw_image"] == bridge.SENSOR_QOS
    assert qos["MS", "/eye_control"] == qos["MP", "/face_position"] == bridge.DEFAULT_QOS
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
        controller: Process,
        diag: Collector[m.DiagnosticStatus]) -> None:
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    expressions.wait_for(timeout=30, what="the controller's own expression")

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


@pytest.mark.integration
def test_radar_targets_reach_a_ros_2_peer_as_a_pose_array(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node) -> None:
    """An LD2450 report on `radar/<device>/targets` arrives on `/ld2450_targets`
    as a PoseArray in the radar's frame, the same bytes an exported bag holds."""
    token = next(t for t in started if t.name == "/ld2450_targets")
    assert (token.kind, token.type_name, token.type_hash, token.qos) == (
        "MP", "geometry_msgs::msg::dds_::PoseArray_", TARGETS.type_hash, bridge.DEFAULT_QOS)
    got: list[bytes] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        got.append(sample.payload.to_bytes())
        arrived.set()

    peer.declare_subscriber(TARGETS.key, on_sample)
    publisher = probe.publisher(keys.RADAR_TARGETS, device="2")

    def target(slot: int, x_m: float, y_m: float) -> m.RadarTarget:
        return m.RadarTarget(slot=slot, x_m=x_m, y_m=y_m, speed_mps=0.1, resolution_m=0.3,
                             position=m.Point(x=y_m, y=-x_m, z=0.0), bearing_rad=0.0,
                             distance_m=1.0)

    report = m.RadarTargets(stamp_ns=m.now_ns(), device_id=2, radar_id=1,
                            targets=[target(0, -0.4, 1.5), target(2, 1.0, 2.0)])

    def sent() -> bool:
        publisher.put(report)
        return arrived.wait(0.2)

    retry_until(sent, 30, 0.0, "/ld2450_targets at the raw peer")
    decoded = their_decoder(types.POSE_ARRAY,
                            STANDARD[types.POSE_ARRAY] + DEPENDENCIES + POSES)(got[0])
    assert decoded.header.frame_id == "radar_2_1"
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == divmod(
        report.stamp_ns, 10**9)
    assert [(p.position.x, p.position.y, p.position.z, p.orientation.w)
            for p in decoded.poses] == [(1.5, 0.4, 0.0, 1.0), (2.0, -1.0, 0.0, 1.0)]
    assert got[0] == rosbag.to_ros(rosbag.BY_NAME["/ld2450_targets"], report)[1]


def subscription_token(peer: zenoh.Session, route: bridge.Route,
                       domain_id: int = SETTINGS.domain_id,
                       qos: wire.Qos = bridge.SENSOR_QOS) -> str:
    """The `MS` graph token a ROS 2 node subscribing to `route` would declare."""
    return wire.GraphToken(
        domain_id=domain_id, session_id=str(peer.info.zid()), node_id=0, entity_id=1,
        kind="MS", enclave="", namespace="/", node_name="viewer", name=route.ros_name,
        type_name=wire.dds_type_name(route.ros_type), type_hash=route.type_hash,
        qos=qos).format()


@pytest.mark.integration
def test_images_flow_only_while_a_ros_2_subscription_is_in_the_graph(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node,
        diag: Collector[m.DiagnosticStatus]) -> None:
    camera = probe.publisher(keys.CAMERA_IMAGE, camera="front")
    assert not camera.has_subscribers(), "the bridge reads the frames with nobody watching"
    got: list[bytes] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        got.append(sample.payload.to_bytes())
        arrived.set()

    peer.declare_subscriber(RAW_IMAGE.key, on_sample)
    token = peer.liveliness().declare_token(subscription_token(peer, RAW_IMAGE))
    pixels = bytes(range(256)) * 3 * 4  # 32 x 24 x 3
    frame = m.Image(stamp_ns=m.now_ns(), frame_id="front", width=32, height=24, encoding="bgr8",
                    data=pixels)

    def sent() -> bool:
        camera.put(frame)
        return arrived.wait(0.2)

    retry_until(sent, 30, 0.0, "/raw_image at the peer once it subscribed")
    decoded = their_decoder(types.IMAGE, STANDARD[types.IMAGE] + DEPENDENCIES)(got[0])
    assert (decoded.width, decoded.height, decoded.encoding, decoded.step) == (32, 24, "bgr8", 96)
    assert bytes(decoded.data) == pixels
    retry_until(lambda: counter(diag, "readers /raw_image") == 1, 30, 0.2, "one reader")

    token.undeclare()
    retry_until(lambda: not camera.has_subscribers(), 30, 0.2,
                "the bridge's frame subscription closed with the last reader")
    retry_until(lambda: counter(diag, "readers /raw_image") == 0, 30, 0.2, "no reader")


@pytest.mark.integration
def test_a_late_ros_2_subscriber_gets_the_latched_lids(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node,
        diag: Collector[m.DiagnosticStatus]) -> None:
    """Transient local as rmw_zenoh does it: the bridge's advanced publisher keeps
    the last value; a subscriber declared later asks its history."""
    lids = m.EyeLidControl(stamp_ns=m.now_ns(), eye_id=m.EyeId.LEFT, top_lid_position=40.0,
                           bottom_lid_position=5.0)
    probe.publisher(keys.LIDS).put(lids)
    retry_until(lambda: counter(diag, "sent /eye_lid_control") >= 1, 30, 0.2,
                "the lids sent to ROS 2")

    decode = their_decoder(LIDS.ros_type, schema_of_ours("EyeLidControl"))
    first = decode(late_sample(peer, LIDS.key))
    assert (first.eye_id, first.top_lid_position, first.bottom_lid_position) == (
        int(m.EyeId.LEFT), 40.0, 5.0)


def late_sample(session: zenoh.Session, key: str) -> bytes:
    """The first sample a transient-local ROS 2 subscription declared now gets:
    an advanced subscriber with history and late-publisher detection, as
    rmw_zenoh's are."""
    got: list[bytes] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        got.append(sample.payload.to_bytes())
        arrived.set()

    subscriber = zenoh.ext.declare_advanced_subscriber(
        session, key, on_sample, history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
    try:
        assert arrived.wait(30), f"no history on {key} for the late subscriber"
        return got[0]
    finally:
        subscriber.undeclare()


@pytest.mark.integration
def test_a_ros_2_gaze_moves_the_eyes_and_a_flood_is_cut(
        started: list[wire.GraphToken], peer: zenoh.Session, probe: Node,
        controller: Process,
        diag: Collector[m.DiagnosticStatus]) -> None:
    control = Collector[m.EyeControl](probe, keys.EYE_CONTROL)
    encode: Any = their_encoder(bridge.EYE_CONTROL, schema_of_ours("EyeControl"))
    look = encode({"stamp_ns": 5, "yaw": 0.4, "pitch": -0.2, "target_distance_cm": 80.0})
    gid = bytes(16)
    sequence = iter(range(1, 1_000_000))

    def looked() -> m.EyeControl | None:
        # Sent again until seen, as a ROS 2 gaze is: the arbiter's sample on
        # eyes/control is not ordered after this test's subscription to it.
        peer.put(EYE_CONTROL.key, look,
                 attachment=wire.Attachment(next(sequence), m.now_ns(), gid).encode())
        try:
            return control.wait_for(lambda c: c.yaw == 0.4 and c.pitch == -0.2, 1.0)
        except TimeoutError:
            return None
    seen = retry_until(looked, 30, 0.0, "the ROS 2 gaze on eyes/control")
    assert seen.target_distance_cm == 80.0

    # Far beyond the burst and 50/s. BLOCK: every sample reaches the bridge, however
    # slowly a busy machine sends them; the limiter cannot have taken in more than
    # its burst and rate allow over the time since the flood began.
    flood = 2000
    began = time.monotonic()
    for _ in range(flood):
        peer.put(EYE_CONTROL.key, b"\x00\x01\x00\x00flood",
                 congestion_control=zenoh.CongestionControl.BLOCK,
                 attachment=wire.Attachment(next(sequence), m.now_ns(), gid).encode())

    def allowed() -> float:
        return SETTINGS.incoming_burst + SETTINGS.max_incoming_hz * (time.monotonic() - began)
    retry_until(lambda: counter(diag, "flooded") >= flood - allowed(), 30, 0.2,
                "the flood counted")
    assert counter(diag, "malformed") <= allowed(), "more than the rate was decoded"


@pytest.mark.integration
def test_one_ros_2_sample_holds_the_eyes_only_until_the_peer_goes_quiet(
        spawn: Callable[..., Process], peer: zenoh.Session, probe: Node,
        controller: Process, tmp_path: Path) -> None:
    """One /screen_expression used to keep the bridge's lease until shutdown (the
    eyes on LOVE for good); now the lease ends `lease_idle_s` after the last
    sample, and the robot's own expression is back."""
    expressions = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
    own = expressions.wait_for(timeout=30, what="the controller's own expression").action
    leases = Collector[m.Leases](probe, keys.LEASES)
    config = tmp_path / "ros2.toml"
    config.write_text("[ros2]\nlease_idle_s = 1.0\n")
    spawn("ros2-bridge", "--domain-id", str(SETTINGS.domain_id), "--config", str(config))
    retry_until(lambda: sum(t.kind == "MS" for t in graph(peer)) == 2 or None, 30, 0.2,
                "the bridge's graph tokens")
    encode: Any = their_encoder(bridge.EXPRESSION, schema_of_ours("ScreenExpression"))
    love = encode({"stamp_ns": 5, "action": int(m.ExpressionAction.ANIMATE_LOVE)})
    peer.put(EXPRESSION.key, love, attachment=wire.Attachment(1, m.now_ns(), bytes(16)).encode())
    expressions.wait_for(lambda e: e.action == m.ExpressionAction.ANIMATE_LOVE, 30,
                         "LOVE from the ROS 2 peer")
    expressions.clear()
    ended = leases.wait_for(lambda s: any(e.holder == "ros2-bridge" and "no ROS 2 command"
                                          in e.message for e in s.ended), 30,
                            "the bridge's lease given back when the peer went quiet")
    assert not any(x.holder == "ros2-bridge" for x in ended.leases)
    expressions.wait_for(lambda e: e.action == own, 30, f"the robot's own {own.name} back")


MAPPED_BLOCKS = """
import ctypes, sys
from buddybot.ros2 import service

class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype, libc.malloc.restype = Info, ctypes.c_void_p
libc.malloc.argtypes, libc.free.argtypes = [ctypes.c_size_t], [ctypes.c_void_p]
if sys.argv[1] == "keep":
    assert service.keep_freed_frames()
before = libc.mallinfo2().hblks
block = libc.malloc(8 << 20)
print(libc.mallinfo2().hblks - before)
libc.free(block)
"""


@pytest.mark.integration
@pytest.mark.parametrize(("mode", "mapped"), [("keep", "0"), ("default", "1")])
def test_the_heap_keeps_frame_sized_blocks(mode: str, mapped: str) -> None:
    """With the bridge's heap settings an 8 MiB block (a large frame) comes from
    glibc's heap, not a mapping of its own (glibc's default, measured too)."""
    out = subprocess.run([sys.executable, "-c", MAPPED_BLOCKS, mode], capture_output=True,
                         text=True, timeout=60, check=True)
    assert out.stdout.strip() == mapped


def test_without_glibc_nothing_changes(monkeypatch: pytest.MonkeyPatch) -> None:
    def no_libc(_name: object) -> object:
        raise OSError("no C library")

    monkeypatch.setattr(service.ctypes, "CDLL", no_libc)
    assert not service.keep_freed_frames()
