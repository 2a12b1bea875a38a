"""`ros2/rosbag.py`: the bag table, ros2msg definitions (parsed by mcap-ros2-support,
an implementation that is not ours), the schema check on import, QoS and metadata
(read back by rosbags' rosbag2 reader and held equal to the live bridge's)."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from mcap_ros2.decoder import DecoderFactory
from rosbags.interfaces import QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.rosbag2 import Reader as RosbagsReader

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, hri, rosbag, types, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.tools.testing import visitor
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
        elif ros_type == types.COMPRESSED_IMAGE:  # /debug_image: compressed, as the bridge
            assert entry.name == "debug_image" and decoded.format == "jpeg"
        elif ros_type == types.POSE_ARRAY:
            assert decoded.header.frame_id == "radar_0_1" and len(decoded.poses) == 1
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
    poses = rosbag.message_definition(types.POSE_ARRAY).encode()
    assert "written only" in str(rosbag.accept_channel("/ld2450_targets", types.POSE_ARRAY,
                                                       "ros2msg", poses, "cdr"))


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
    latched = rosbag.qos_profile(bridge.LATCHED_QOS)
    assert (latched["durability"], latched["depth"]) == ("transient_local", 1)
    assert rosbag.qos_profile(bridge.DEFAULT_QOS)["durability"] == "volatile"
    sensor = rosbag.qos_profile(bridge.SENSOR_QOS)
    assert (sensor["reliability"], sensor["depth"]) == ("best_effort", 5)
    with pytest.raises(ValueError, match="not written to a bag"):
        rosbag.qos_profile(wire.Qos(deadline_sec=1))
    writer = rosbag.Rosbag2Writer(tmp_path / "visit")
    writer.write("buddybot/buddy/audio/device_free", keys.DEVICE_FREE,
                 m.Bool(stamp_ns=5, data=True), 1_000)
    writer.write("buddybot/buddy/leases/state", keys.LEASES,
                 m.Leases(stamp_ns=5, leases=[]), 2_000)
    writer.close()
    info = yaml.safe_load((tmp_path / "visit" / "metadata.yaml").read_text())
    bag = info["rosbag2_bagfile_information"]
    assert bag["version"] == 9 and bag["storage_identifier"] == "mcap"
    assert bag["relative_file_paths"] == ["visit_0.mcap"] and bag["message_count"] == 1
    (topic,) = bag["topics_with_message_count"]
    assert topic["topic_metadata"]["type_description_hash"] == types.type_hash(types.BOOL)
    assert topic["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "reliable"
    assert writer.stats.skipped == {"buddybot/buddy/leases/state": "no ROS 2 topic"}


def test_people_are_written_as_the_bridge_publishes_them(tmp_path: Path) -> None:
    """`people/state` becomes the ROS4HRI topics, on change, with the bridge's QoS;
    read back by mcap-ros2-support's decoder from the bag's own schemas."""
    writer = rosbag.Rosbag2Writer(tmp_path / "visit")
    ada = visitor(True, 3, 1.5, face=True).people[0]
    ada = msgspec.structs.replace(ada, yaw_rad=0.2, engagement="ENGAGED", name="Ada")
    for i, people in enumerate(([ada], [ada], [])):
        writer.write("buddybot/buddy/people/state", keys.PEOPLE_STATE,
                     m.PeopleState(stamp_ns=1_700_000_000_000_000_000 + i * 200_000_000,
                                   people=people),
                     1_000 + i)
    writer.close()
    info = yaml.safe_load((tmp_path / "visit" / "metadata.yaml").read_text())
    topics = {t["topic_metadata"]["name"]: t for t in
              info["rosbag2_bagfile_information"]["topics_with_message_count"]}
    assert topics["/humans/persons/tracked"]["message_count"] == 2  # [p3], then []
    assert topics["/humans/persons/p3/engagement_status"]["message_count"] == 1
    assert topics["/tf"]["message_count"] == 2
    for name, topic in topics.items():
        assert topic["topic_metadata"]["offered_qos_profiles"] == [
            rosbag.qos_profile(hri.qos(name[1:]))], name
    with (tmp_path / "visit" / "visit_0.mcap").open("rb") as stream:
        read = [(c.topic, msg) for _s, c, _m, msg in make_reader(
            stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    tracked = [msg.ids for topic, msg in read if topic == "/humans/persons/tracked"]
    assert tracked == [["p3"], []]
    assert [msg.data for topic, msg in read if topic == "/humans/persons/p3/alias"] == [
        "known_ada"]


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


SETTINGS = [Ros2Settings(), Ros2Settings(raw_image="compressed")]
RMW_DEFAULT = {"reliability": wire.RELIABLE, "durability": wire.VOLATILE, "history": 1,
               "depth": 10}
"""What an empty component of a graph token's QoS means (rmw's default profile)."""


def _jpeg_frame() -> m.Image:
    """A camera frame as a recording holds it (JPEG)."""
    import cv2
    import numpy as np

    pixels = np.full((4, 6, 3), (30, 120, 220), np.uint8)
    ok, buf = cv2.imencode(".jpg", pixels)
    assert ok
    return m.Image(stamp_ns=m.now_ns(), frame_id="camera_front", width=6, height=4,
                   encoding="jpeg", data=buf.tobytes())


def _bag_of_every_topic(directory: Path, settings: Ros2Settings) -> Path:
    by_type: dict[type, m.Message] = {type(x): x for x in sample_messages()}
    by_type[m.Image] = _jpeg_frame()
    writer = rosbag.Rosbag2Writer(directory, settings)
    for i, entry in enumerate(rosbag.TABLE):
        assert writer.write(f"buddybot/buddy/{entry.name}", entry.topic,
                            by_type[entry.topic.type], 1_000 + i), writer.stats.skipped
    writer.close()
    return directory


@pytest.mark.parametrize("settings", SETTINGS, ids=lambda s: s.raw_image)
def test_a_bag_offers_every_topic_with_the_bridges_type_and_qos(
        tmp_path: Path, settings: Ros2Settings) -> None:
    """rosbags reads metadata.yaml; each topic's type and offered QoS are the
    ones the live bridge's publisher announces under the same settings (its
    graph token's QoS, an empty component being rmw's default). A QoS or a
    type defined apart from the bridge's table fails here."""
    path = _bag_of_every_topic(tmp_path / "bag", settings)
    live = {f"/{o.name}": o for o in bridge.outgoing(settings)}
    with RosbagsReader(path) as reader:
        connections = {c.topic: c for c in reader.connections}
    assert set(connections) == {e.ros_name for e in rosbag.TABLE}
    assert set(connections) <= set(live), "a bag topic the bridge does not publish"
    for name, connection in connections.items():
        out = live[name]
        assert connection.msgtype == out.ros_type, name
        (qos,) = connection.ext.offered_qos_profiles
        want = {k: RMW_DEFAULT[k] if getattr(out.qos, k) is None else getattr(out.qos, k)
                for k in RMW_DEFAULT}
        got = {"reliability": qos.reliability.value, "durability": qos.durability.value,
               "history": qos.history.value, "depth": qos.depth}
        assert got == want, name
        assert qos.liveliness == QosLiveliness.AUTOMATIC
        assert qos.deadline == qos.lifespan == qos.liveliness_lease_duration == (
            9223372036, 854775807)
    profile = {n: c.ext.offered_qos_profiles[0] for n, c in connections.items()}
    for name in ("/radar_presence", "/screen_expression", "/eye_lid_control",
                 "/audio_device_is_free"):  # as the bridge offers them: depth 1
        assert (profile[name].durability, profile[name].depth) == (
            QosDurability.TRANSIENT_LOCAL, 1)
    for name in ("/raw_image", "/debug_image"):  # the sensor profile
        assert (profile[name].reliability, profile[name].depth) == (
            QosReliability.BEST_EFFORT, 5)
    assert profile["/face_position"].history == QosHistory.KEEP_LAST


@pytest.mark.parametrize("settings", SETTINGS, ids=lambda s: s.raw_image)
def test_each_mcap_channel_carries_the_metadata_yamls_qos(tmp_path: Path,
                                                          settings: Ros2Settings) -> None:
    """`ros2 bag play DIR/DIR_0.mcap` reads the channel's own profile: the same."""
    path = _bag_of_every_topic(tmp_path / "bag", settings)
    info = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    from_yaml = {t["topic_metadata"]["name"]: t["topic_metadata"]["offered_qos_profiles"]
                 for t in info["topics_with_message_count"]}
    with open(path / "bag_0.mcap", "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    channels = {c.topic: yaml.safe_load(c.metadata["offered_qos_profiles"])
                for c in summary.channels.values()}
    assert channels == from_yaml and len(channels) == len(rosbag.TABLE)


def test_raw_image_follows_the_setting_and_import_takes_both(tmp_path: Path) -> None:
    """The recorded JPEG is an Image (decoded) or a CompressedImage (as it is),
    as the bridge would publish it; `bag import` takes either back."""
    frame = _jpeg_frame()
    entry = rosbag.BY_NAME["/raw_image"]
    raw_type, raw = rosbag.to_ros(entry, frame)
    small_type, small = rosbag.to_ros(entry, frame, Ros2Settings(raw_image="compressed"))
    assert (raw_type, small_type) == (types.IMAGE, types.COMPRESSED_IMAGE)
    pixels = rosbag.from_ros(entry, raw_type, raw, 0)
    assert (pixels.encoding, pixels.width, pixels.height, len(pixels.data)) == (
        "bgr8", 6, 4, 72)
    assert pixels.data == convert.decoded_image(frame).data
    assert rosbag.from_ros(entry, small_type, small, 0) == frame
    assert set(entry.ros_types) == {types.IMAGE, types.COMPRESSED_IMAGE}
