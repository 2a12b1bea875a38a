"""`ros2/rosbag.py`: the bag table, ros2msg definitions (parsed by mcap-ros2-support,
an implementation that is not ours), the schema check on import, QoS and metadata."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, rosbag, types
from tests.contract.test_messages import sample_messages


def test_names_and_types_agree_with_the_bridge() -> None:
    for out in bridge.OUTGOING:
        entry = rosbag.BY_TOPIC[out.topic]
        assert entry.name == out.name and out.ros_type in entry.ros_types


def test_every_mapped_type_has_a_definition_mcap_ros2_round_trips() -> None:
    """Each schema text parses with mcap-ros2-support's own .msg parser, and a
    message we encode decodes with it to the same values."""
    by_type = {type(x): x for x in sample_messages()}
    for entry in rosbag.TABLE:
        message = by_type[entry.topic.type]
        ros_type, payload = rosbag.to_ros(entry, message)
        text = rosbag.message_definition(ros_type)
        decoded = generate_dynamic(ros_type, text)[ros_type](payload)
        if ros_type == types.POINT_STAMPED:
            assert (decoded.point.x, decoded.header.frame_id) == (1.0, "cam")
        elif ros_type == types.BOOL:
            assert decoded.data is message.data  # type: ignore[attr-defined]
        elif ros_type == types.IMAGE:
            assert (decoded.width, decoded.encoding) == (2, "bgr8")
        else:
            assert decoded.stamp_ns == message.stamp_ns  # type: ignore[attr-defined]
        assert rosbag.check_definition(text, ros_type) == ""


def test_the_definition_has_rosbag2s_layout() -> None:
    text = rosbag.message_definition(types.POINT_STAMPED)
    assert text.startswith("std_msgs/Header header\n")
    assert f"\n{'=' * 80}\nMSG: std_msgs/msg/Header\n" in text
    assert f"\n{'=' * 80}\nMSG: builtin_interfaces/msg/Time\n" in text
    ours = rosbag.message_definition(convert.OURS[m.LD2410TargetDataFrameArray])
    assert "MSG: buddybot_interfaces/msg/LD2410TargetDataFrame\n" in ours


def test_a_definition_other_than_ours_is_named() -> None:
    pupil = convert.OURS[m.PupilControl]
    seed_like = "uint64 stamp_ns\nfloat32 dilation_percentage\n"  # float32: not our wire
    assert "other field types" in rosbag.check_definition(seed_like, pupil)
    assert "otherwise" in rosbag.check_definition("bool value\n", types.BOOL)
    assert "does not parse" in rosbag.check_definition("@@@ x\n", types.BOOL)
    assert "without the definition of std_msgs/msg/Header" in rosbag.check_definition(
        "std_msgs/Header header\ngeometry_msgs/Point point\n", types.POINT_STAMPED)
    assert "limit" in rosbag.check_definition("#" * (rosbag.MAX_SCHEMA_BYTES + 1), types.BOOL)
    # ROS 1 style dependency names, which some writers use, are read too
    legacy = rosbag.message_definition(types.POINT_STAMPED).replace(
        "MSG: std_msgs/msg/Header", "MSG: std_msgs/Header")
    assert rosbag.check_definition(legacy, types.POINT_STAMPED) == ""


def test_channels_are_told_apart_before_any_message() -> None:
    good = rosbag.message_definition(types.BOOL).encode()
    taken = rosbag.accept_channel("/audio_device_is_free", types.BOOL, "ros2msg", good, "cdr")
    assert isinstance(taken, rosbag.Accepted) and taken.entry.topic is keys.DEVICE_FREE
    assert rosbag.accept_channel("/tf", types.BOOL, "ros2msg", good, "cdr") \
        == "no BuddyBot key for this topic"
    assert "only cdr" in str(rosbag.accept_channel("/audio_device_is_free", types.BOOL,
                                                   "ros2msg", good, "json"))
    assert "taken here" in str(rosbag.accept_channel("/audio_device_is_free",
                                                     "std_msgs/msg/String", "ros2msg",
                                                     good, "cdr"))
    assert "only ros2msg" in str(rosbag.accept_channel("/audio_device_is_free", types.BOOL,
                                                       "ros2idl", good, "cdr"))
    assert "UTF-8" in str(rosbag.accept_channel("/audio_device_is_free", types.BOOL,
                                                "ros2msg", b"\xff\xfe", "cdr"))


def test_imported_messages_are_checked_and_keyed() -> None:
    entry = rosbag.BY_NAME["/ld2410_target_frames"]
    frames = m.LD2410TargetDataFrameArray(stamp_ns=m.now_ns(), device_id=3, sensors=[])
    ros_type, payload = rosbag.to_ros(entry, frames)
    back = rosbag.from_ros(entry, ros_type, payload, 0)
    assert back == frames and rosbag.relative_key(entry, back, "front") == "radar/3/frames"
    face = rosbag.BY_NAME["/face_position"]
    assert rosbag.relative_key(face, back, "side") == "camera/side/face"
    with pytest.raises(convert.ConvertError):
        rosbag.from_ros(entry, ros_type, payload[:-3], 0)
    with pytest.raises(convert.ConvertError, match="not taken here"):
        rosbag.from_ros(entry, types.BOOL, payload, 0)
    expression = rosbag.BY_NAME["/screen_expression"]
    bad = serialize_dynamic(ros_type := convert.OURS[m.ScreenExpression],
                            rosbag.message_definition(ros_type))[ros_type](
        {"stamp_ns": 1, "action": 99})
    with pytest.raises(convert.ConvertError):  # action 99 is outside the contract
        rosbag.from_ros(expression, ros_type, bad, 0)


def test_qos_and_metadata_read_as_yaml(tmp_path: Path) -> None:
    assert rosbag.qos_profile(keys.PRESENCE)["durability"] == "transient_local"
    assert rosbag.qos_profile(keys.FACE)["durability"] == "volatile"
    writer = rosbag.Rosbag2Writer(tmp_path / "visit")
    writer.write("buddybot/buddy/audio/device_free", keys.DEVICE_FREE,
                 m.Bool(stamp_ns=5, data=True), 1_000)
    writer.write("buddybot/buddy/people/state", keys.PEOPLE_STATE,
                 m.PeopleState(stamp_ns=5, people=[]), 2_000)
    writer.close()
    info = yaml.safe_load((tmp_path / "visit" / "metadata.yaml").read_text())
    bag = info["rosbag2_bagfile_information"]
    assert bag["version"] == 9 and bag["storage_identifier"] == "mcap"
    assert bag["relative_file_paths"] == ["visit_0.mcap"] and bag["message_count"] == 1
    (topic,) = bag["topics_with_message_count"]
    assert topic["topic_metadata"]["type_description_hash"] == types.type_hash(types.BOOL)
    assert topic["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "reliable"
    assert writer.stats.skipped == {"buddybot/buddy/people/state": "no ROS 2 topic"}


def test_an_existing_output_is_not_overwritten(tmp_path: Path) -> None:
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("mine")
    with pytest.raises(rosbag.Ros2BagError, match="not an empty directory"):
        rosbag.Rosbag2Writer(tmp_path / "full")
    (tmp_path / "file").write_text("mine")
    with pytest.raises(rosbag.Ros2BagError):
        rosbag.Rosbag2Writer(tmp_path / "file")


def test_split_bags_are_read_in_order(tmp_path: Path) -> None:
    for name in ("b_10.mcap", "b_2.mcap", "b_0.mcap", "metadata.yaml"):
        (tmp_path / name).write_text("")
    assert [p.name for p in rosbag.mcap_files(tmp_path)] == ["b_0.mcap", "b_2.mcap",
                                                             "b_10.mcap"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(rosbag.Ros2BagError, match=r"without \.mcap"):
        rosbag.mcap_files(tmp_path / "empty")
