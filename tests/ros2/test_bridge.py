"""The bridge's tables (services/ros2/bridge.py): our keys <-> ROS 2 topics, pure."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.ros2 import bridge, types, wire
from buddybot.ros2.settings import Ros2Settings


def test_outgoing_is_the_seeds_names_and_types() -> None:
    table = {(o.topic.pattern, o.name, o.ros_type) for o in bridge.OUTGOING}
    ours = "buddybot_interfaces/msg/"
    assert table == {
        ("camera/{camera}/face", "face_position", "geometry_msgs/msg/PointStamped"),
        ("camera/{camera}/image", "raw_image", "sensor_msgs/msg/Image"),
        ("camera/{camera}/debug_image", "debug_image", "sensor_msgs/msg/CompressedImage"),
        ("radar/{device}/frames", "ld2410_target_frames", ours + "LD2410TargetDataFrameArray"),
        ("radar/{device}/targets", "ld2450_targets", "geometry_msgs/msg/PoseArray"),
        ("radar/presence", "radar_presence", ours + "PresenceDetection"),
        ("eyes/expression", "screen_expression", ours + "ScreenExpression"),
        ("eyes/control", "eye_control", ours + "EyeControl"),
        ("eyes/direction", "eyes_direction_control", ours + "EyesDirection"),
        ("eyes/pupil", "pupil_control", ours + "PupilControl"),
        ("eyes/lids", "eye_lid_control", ours + "EyeLidControl"),
        ("audio/device_free", "audio_device_is_free", "std_msgs/msg/Bool"),
    }
    assert len({o.name for o in bridge.OUTGOING}) == len(bridge.OUTGOING)


def test_latched_keys_are_transient_local_and_images_on_demand() -> None:
    latched = {o.name for o in bridge.OUTGOING if o.latched}
    assert latched == {"radar_presence", "screen_expression", "eye_lid_control",
                       "audio_device_is_free"}
    assert latched == {o.name for o in bridge.OUTGOING if o.topic.latched}
    for out in bridge.OUTGOING:
        if out.latched:
            assert out.qos.format() == ":1:,1:,:,:,,"
            assert bridge.cache(out.qos) == 1
        else:
            assert bridge.cache(out.qos) is None
    images = {o.name for o in bridge.OUTGOING if o.on_demand}
    assert images == {"raw_image", "debug_image"}
    assert {o.qos.format() for o in bridge.OUTGOING if o.on_demand} == {"2::,5:,:,:,,"}
    assert {o.qos for o in bridge.OUTGOING if not (o.latched or o.on_demand)} == {
        bridge.DEFAULT_QOS}


def test_raw_image_is_compressed_when_the_settings_ask() -> None:
    raw = {o.name: o for o in bridge.outgoing(Ros2Settings())}["raw_image"]
    compressed = {o.name: o for o in bridge.outgoing(Ros2Settings(raw_image="compressed"))}
    assert raw.ros_type == types.IMAGE
    assert compressed["raw_image"].ros_type == types.COMPRESSED_IMAGE
    assert [o.name for o in bridge.outgoing(Ros2Settings(raw_image="compressed"))] == [
        o.name for o in bridge.OUTGOING]


def test_incoming_takes_expression_and_gaze_under_their_leases() -> None:
    assert [(i.name, i.ros_type, i.resource, i.latest) for i in bridge.INCOMING] == [
        ("screen_expression", "buddybot_interfaces/msg/ScreenExpression", "expression", False),
        ("eye_control", "buddybot_interfaces/msg/EyeControl", "gaze", True)]


BGR = m.Image(stamp_ns=5, frame_id="front", width=4, height=2, encoding="bgr8",
              data=bytes(range(24)))
SAMPLES: dict[str, m.Message] = {
    "camera/{camera}/face": m.FacePosition(stamp_ns=5, frame_id="front",
                                           point=m.Point(x=1.0, y=0.5, z=0.2), confidence=0.9),
    "camera/{camera}/image": BGR,
    "camera/{camera}/debug_image": BGR,
    "radar/{device}/frames": m.LD2410TargetDataFrameArray(stamp_ns=5, device_id=0, sensors=[]),
    "radar/{device}/targets": m.RadarTargets(stamp_ns=5, device_id=0, radar_id=1, targets=[
        m.RadarTarget(slot=0, x_m=-0.4, y_m=1.5, speed_mps=0.0, resolution_m=0.32,
                      position=m.Point(x=1.5, y=0.4, z=0.0), bearing_rad=0.26,
                      distance_m=1.55)]),
    "radar/presence": m.PresenceDetection(
        stamp_ns=5, target_state=m.PresenceTarget.STANDING,
        presence_state=m.PresenceState.IN_RANGE, distance_m=1.5),
    "eyes/expression": m.ScreenExpression(stamp_ns=5, action=m.ExpressionAction.EYE_GRIN),
    "eyes/control": m.EyeControl(stamp_ns=5, yaw=0.1, pitch=0.0, target_distance_cm=90.0),
    "eyes/direction": m.EyesDirection(stamp_ns=5, yaw=5.0, pitch=1.0),
    "eyes/pupil": m.PupilControl(stamp_ns=5, dilation_percentage=40.0),
    "eyes/lids": m.EyeLidControl(stamp_ns=5, eye_id=m.EyeId.BOTH, top_lid_position=10.0,
                                 bottom_lid_position=0.0),
    "audio/device_free": m.Bool(stamp_ns=5, data=True),
}


@pytest.mark.parametrize("out", [*bridge.OUTGOING, bridge.RAW_IMAGE_COMPRESSED],
                         ids=lambda o: f"{o.name}:{o.ros_type.rsplit('/', 1)[1]}")
def test_every_outgoing_encoder_takes_its_topics_message(out: bridge.Outgoing) -> None:
    msg = SAMPLES[out.topic.pattern]
    assert isinstance(msg, out.topic.type)
    payload = out.encode(msg)
    assert wire.encapsulation(payload) == "CDR_LE"
    assert types.typestore().deserialize_cdr(payload, out.ros_type) is not None


def test_incoming_decode_and_refuse_garbage() -> None:
    expression, gaze = bridge.INCOMING
    sad = m.ScreenExpression(stamp_ns=5, action=m.ExpressionAction.EYE_SAD)
    look = m.EyeControl(stamp_ns=5, yaw=-0.2, pitch=0.1, target_distance_cm=70.0)
    assert expression.decode(bridge.convert.to_ros(sad)[1]) == sad
    assert gaze.decode(bridge.convert.to_ros(look)[1]) == look
    for inc in bridge.INCOMING:
        with pytest.raises(bridge.convert.ConvertError):
            inc.decode(b"\x00\x01\x00\x00\xff")
    with pytest.raises(bridge.convert.ConvertError):  # the other topic's bytes
        gaze.decode(bridge.convert.to_ros(sad)[1])


@pytest.mark.parametrize(("namespace", "name"), [("/", "/face_position"),
                                                  ("/robot1", "/robot1/face_position"),
                                                  ("/a/b", "/a/b/face_position")])
def test_names_live_in_the_namespace(namespace: str, name: str) -> None:
    assert bridge.fully_qualified(namespace, "face_position") == name


def test_route_spells_rmw_zenohs_key_in_the_domain() -> None:
    r = bridge.route(Ros2Settings(domain_id=7, namespace="/robot1"), "face_position",
                     types.POINT_STAMPED)
    assert r.key == ("7/robot1/face_position/geometry_msgs::msg::dds_::PointStamped_/"
                     f"{types.type_hash(types.POINT_STAMPED)}")
    assert r.any_type_key == "7/robot1/face_position/*/*"
    assert bridge.split_key(r.key) == ("geometry_msgs::msg::dds_::PointStamped_", r.type_hash)
    with pytest.raises(wire.WireError):
        bridge.split_key("face_position")


@pytest.mark.parametrize("table", [{"domain_id": 233}, {"domain_id": -1},
                                   {"namespace": "robot"}, {"namespace": "/robot/"},
                                   {"namespace": "/1robot"}, {"colour": "red"}])
def test_settings_refuse_what_ros_would_not_take(table: dict[str, object]) -> None:
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert(table, Ros2Settings)


def test_settings_default_to_off_domain_0_root() -> None:
    assert msgspec.convert({}, Ros2Settings) == Ros2Settings(enabled=False, domain_id=0,
                                                            namespace="/")
