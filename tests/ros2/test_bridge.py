"""The bridge's tables (services/ros2/bridge.py): our keys <-> ROS 2 topics, pure."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, types, wire
from buddybot.ros2.settings import Ros2Settings


def test_outgoing_is_the_seeds_names_and_types() -> None:
    table = {(o.topic.pattern, o.name, o.ros_type) for o in bridge.OUTGOING}
    assert table == {
        ("camera/{camera}/face", "face_position", "geometry_msgs/msg/PointStamped"),
        ("radar/presence", "radar_presence", "buddybot_interfaces/msg/PresenceDetection"),
        ("eyes/expression", "screen_expression", "buddybot_interfaces/msg/ScreenExpression"),
        ("audio/device_free", "audio_device_is_free", "std_msgs/msg/Bool"),
    }


def test_incoming_takes_screen_expression_only() -> None:
    assert [(i.name, i.ros_type) for i in bridge.INCOMING] == [
        ("screen_expression", "buddybot_interfaces/msg/ScreenExpression")]


def test_every_outgoing_encoder_takes_its_topics_message() -> None:
    samples = {
        keys.FACE: m.FacePosition(stamp_ns=5, frame_id="front",
                                  point=m.Point(x=1.0, y=0.5, z=0.2), confidence=0.9),
        keys.PRESENCE: m.PresenceDetection(
            stamp_ns=5, target_state=m.PresenceTarget.STANDING,
            presence_state=m.PresenceState.IN_RANGE, distance_m=1.5),
        keys.EXPRESSION: m.ScreenExpression(stamp_ns=5, action=m.ExpressionAction.EYE_GRIN),
        keys.DEVICE_FREE: m.Bool(stamp_ns=5, data=True),
    }
    for out in bridge.OUTGOING:
        payload = out.encode(samples[out.topic])
        assert wire.encapsulation(payload) == "CDR_LE"
        assert types.typestore().deserialize_cdr(payload, out.ros_type) is not None


def test_incoming_expression_decodes_and_refuses_garbage() -> None:
    (inc,) = bridge.INCOMING
    sad = m.ScreenExpression(stamp_ns=5, action=m.ExpressionAction.EYE_SAD)
    _, payload = bridge.convert.to_ros(sad)
    assert inc.decode(payload) == sad
    with pytest.raises(bridge.convert.ConvertError):
        inc.decode(b"\x00\x01\x00\x00\xff")


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
