"""`buddybot bag export --ros2` and `bag import`, in-process on the real parser:
checked with readers and writers that are not ours (mcap-ros2-support's reader
and writer, rosbags' rosbag2 reader), a round trip, and bad input."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import msgspec
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer
from rosbags.rosbag2 import Reader as RosbagsReader

from buddybot import cli
from buddybot.contract import channels, keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, rosbag, types
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.config import ConfigBase, default_config, parse_config
from buddybot.tools import bag
from tests.tools.mcap_bomb import write_bomb
from tests.tools.test_bag import samples, write_recording

ROBOT = "buddy"


def run(*argv: str, config: ConfigBase | None = None) -> int:
    """One `buddybot bag ...` action in-process (no router is needed)."""
    args: argparse.Namespace = cli.build_parser().parse_args(["bag", *argv])
    return int(args.subverb_main(SimpleNamespace(args=args, robot=ROBOT,
                                                 config=config or default_config())))


@pytest.fixture
def recording(tmp_path: Path) -> tuple[Path, dict[str, tuple[keys.Topic, bytes]], int]:
    """One of our recordings holding every topic of the catalogue once."""
    base = time.time_ns()
    found = samples()
    items = [(key, payload, base + i * 10_000_000)
             for i, (key, (_t, payload)) in enumerate(found.items())]
    write_recording(tmp_path / "visit.mcap", items)
    return tmp_path / "visit.mcap", found, base


def found_people(found: dict[str, tuple[keys.Topic, bytes]]) -> tuple[keys.Topic, bytes]:
    """The recording's `people/state` (topic, payload)."""
    return next(v for v in found.values() if v[0] is keys.PEOPLE_STATE)


def _plain(value: Any) -> Any:
    """An mcap-ros2-support message as builtins (uint8 arrays as lists)."""
    if isinstance(value, bytes | bytearray):
        return list(value)
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "__slots__") or hasattr(value, "__dict__"):
        names = getattr(value, "__slots__", None) or vars(value)
        return {n: _plain(getattr(value, n)) for n in names if not n.startswith("_")}
    return value


def _expected(value: Any) -> Any:
    """Our message (as builtins) as the buddybot_interfaces fields hold it:
    an absent optional is an empty sequence."""
    if isinstance(value, m.Message):
        value = msgspec.to_builtins(value)
    if isinstance(value, dict):
        return {k: [] if v is None else _expected(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_expected(v) for v in value]
    return value


def _same(got: Any, want: Any) -> bool:
    if isinstance(want, dict):
        return all(_same(got[k], v) for k, v in want.items())
    if isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            return False
        return all(_same(g, w) for g, w in zip(got, want, strict=True))
    if isinstance(got, list) and len(got) == 1:  # an optional scalar
        return bool(got[0] == want)
    return bool(got == want)


def test_export_decodes_with_mcap_ros2_to_the_recorded_values(
        recording: tuple[Path, dict[str, tuple[keys.Topic, bytes]], int],
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, found, _base = recording
    assert run("export", "--ros2", str(path), str(tmp_path / "out")) == 0
    err = capsys.readouterr().err
    assert "skipping buddybot/buddy/leases/state: no ROS 2 topic" in err
    assert "exported 18 messages on 18 ROS 2 topics" in err  # people/state: 6 ROS4HRI
    assert "/raw_image as sensor_msgs/msg/Image (raw_image = 'raw'" in err
    recorded = {c.key: c for c in bag.read_info(path).channels}
    log_times = {}
    for item in bag.open_recording(path).messages():
        log_times[item.key] = item.log_time_ns
    seen = set()
    with open(tmp_path / "out" / "out_0.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages())
    people = {channel.topic: ros for _s, channel, _r, ros in decoded
              if channel.topic.startswith("/humans/") or channel.topic == "/tf"}
    (person,) = channels.decode(*found_people(found)).people
    assert people["/humans/persons/tracked"].ids == [f"p{person.id}"]
    decoded = [d for d in decoded if d[1].topic not in people]
    for schema, channel, record, ros in decoded:
        entry = rosbag.BY_NAME[channel.topic]
        key = next(k for k, (t, _p) in found.items() if t is entry.topic)
        topic, payload = found[key]
        ours = channels.decode(topic, channels.from_json(topic, channels.to_json(topic, payload)))
        assert schema is not None and schema.encoding == "ros2msg"
        assert channel.message_encoding == "cdr" and "offered_qos_profiles" in channel.metadata
        assert record.log_time == log_times[key]
        if schema.name == types.POINT_STAMPED:
            assert (ros.point.x, ros.point.y, ros.point.z) == (ours.point.x, ours.point.y,
                                                              ours.point.z)
            assert ros.header.frame_id == ours.frame_id
            assert ros.header.stamp.sec * 10**9 + ros.header.stamp.nanosec == ours.stamp_ns
        elif schema.name == types.COMPRESSED_IMAGE:
            assert ros.format == "jpeg" and bytes(ros.data) == ours.data
        elif schema.name == types.IMAGE:  # the recorded JPEG, decoded as the bridge does
            assert (ros.width, ros.height, ros.encoding) == (ours.width, ours.height, "bgr8")
            assert bytes(ros.data) == _pixels(ours)
        elif schema.name == types.POSE_ARRAY:
            assert ros.header.frame_id == f"radar_{ours.device_id}_{ours.radar_id}"
            assert [(p.position.x, p.position.y) for p in ros.poses] == [
                (t.y_m, -t.x_m) for t in ours.targets]
        elif schema.name == types.BOOL:
            assert ros.data is ours.data
        else:
            assert _same(_plain(ros), _expected(ours)), (key, _plain(ros), _expected(ours))
        seen.add(key)
    assert len(seen) == 12 and all(k in recorded for k in seen)
    with RosbagsReader(tmp_path / "out") as reader:  # rosbags: metadata.yaml and the MCAP
        assert reader.message_count == 12 + len(people)
        assert {c.topic for c in reader.connections} == {e.ros_name for e in rosbag.TABLE} \
            | set(people)
        for connection, _t, raw in reader.messages():
            types.typestore().deserialize_cdr(raw, connection.msgtype)


def _write_ros2(path: Path, stamp: int) -> dict[str, Any]:
    """A ROS 2 recording of the bridge's ROS 2 topics written by mcap-ros2-support."""
    values = {
        "/face_position": (types.POINT_STAMPED, {
            "header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9},
                       "frame_id": "camera_link"},
            "point": {"x": 0.8, "y": -0.1, "z": 0.05}}),
        "/radar_presence": (convert.OURS[m.PresenceDetection], {
            "stamp_ns": stamp, "target_state": 1, "presence_state": 1, "distance_m": 1.5}),
        "/screen_expression": (convert.OURS[m.ScreenExpression],
                               {"stamp_ns": stamp, "action": 3}),
        "/audio_device_is_free": (types.BOOL, {"data": False}),
        "/ld2410_target_frames": (convert.OURS[m.LD2410TargetDataFrameArray], {
            "stamp_ns": stamp, "device_id": 1, "sensors": [{
                "radar_id": 0, "target_state": 1, "movement_distance": 120,
                "movement_energy": 40, "stationary_distance": 130, "stationary_energy": 20,
                "detection_distance": 125, "max_moving_gate": [], "max_stationary_gate": [],
                "moving_gate_energy": [], "stationary_gate_energy": [], "light_level": [],
                "out_pin": []}]}),
        "/tf": (types.BOOL, {"data": True}),  # a topic we do not map
    }
    with open(path, "wb") as stream:
        writer = Ros2Writer(stream)
        schemas = {}
        for i, (topic, (ros_type, value)) in enumerate(values.items()):
            if ros_type not in schemas:
                schemas[ros_type] = writer.register_msgdef(
                    ros_type, rosbag.message_definition(ros_type))
            writer.write_message(topic, schemas[ros_type], value, log_time=stamp + i * 1000)
        writer.finish()
    return values


def test_import_of_mcap_ros2s_file_plays_with_the_same_values(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stamp = m.now_ns()
    _write_ros2(tmp_path / "ros2.mcap", stamp)
    assert run("import", str(tmp_path / "ros2.mcap"), str(tmp_path / "ours.mcap"),
               "--camera", "side") == 0
    err = capsys.readouterr().err
    assert "skipping /tf: no BuddyBot key for this topic" in err
    assert "imported 5 messages from 5 ROS 2 topics" in err
    recording = bag.open_recording(tmp_path / "ours.mcap")  # what `bag play` checks
    got = {item.key: (item.log_time_ns, channels.decode(item.topic, item.payload))
           for item in recording.messages()}
    prefix = f"buddybot/{ROBOT}/"
    face = got[prefix + "camera/side/face"][1]
    assert (face.point.x, face.frame_id, face.stamp_ns) == (0.8, "camera_link", stamp)
    assert got[prefix + "radar/presence"][1].distance_m == 1.5
    assert got[prefix + "eyes/expression"][1].action == m.ExpressionAction.EYE_GRIN
    free = got[prefix + "audio/device_free"]
    assert free[1].data is False and free[1].stamp_ns == free[0] == stamp + 3000
    frames = got[prefix + "radar/1/frames"][1]
    assert frames.sensors[0].movement_distance == 120 and frames.sensors[0].light_level is None


def test_export_then_import_gives_back_the_mapped_keys(
        recording: tuple[Path, dict[str, tuple[keys.Topic, bytes]], int],
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Byte for byte with the JPEG kept (`compressed`); the radar targets,
    written only, are named as skipped."""
    path, _found, _base = recording
    assert run("export", "--ros2", str(path), str(tmp_path / "ros"),
               "--raw-image", "compressed") == 0
    assert run("import", str(tmp_path / "ros"), str(tmp_path / "back.mcap")) == 0
    assert "skipping /ld2450_targets: written only" in capsys.readouterr().err
    before = {i.key: (i.log_time_ns, channels.decode(i.topic, i.payload))
              for i in bag.open_recording(path).messages()
              if i.topic in rosbag.BY_TOPIC and not rosbag.BY_TOPIC[i.topic].not_taken}
    after = {i.key: (i.log_time_ns, channels.decode(i.topic, i.payload))
             for i in bag.open_recording(tmp_path / "back.mcap").messages()}
    assert after.keys() == before.keys()
    for key, (log_time, message) in before.items():
        if isinstance(message, m.FacePosition):  # PointStamped carries no confidence
            message = msgspec.structs.replace(message, confidence=1.0)
        if isinstance(message, m.Bool):  # nor does std_msgs/Bool a stamp: the log time
            message = msgspec.structs.replace(message, stamp_ns=log_time)
        assert after[key] == (log_time, message), key


def _raw_ros2(path: Path, ros_type: str, topic: str, data: bytes, schema: bytes) -> None:
    """A ROS 2 MCAP with one message, written with mcap's plain writer (any bytes)."""
    with open(path, "wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="ros2", library="test")
        sid = writer.register_schema(ros_type, "ros2msg", schema)
        cid = writer.register_channel(topic, "cdr", sid, {"offered_qos_profiles": ""})
        writer.add_message(cid, log_time=m.now_ns(), data=data, publish_time=0)
        writer.finish()


def test_bad_cdr_is_counted_and_skipped(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    ros_type, payload = convert.to_ros(m.PresenceDetection(
        stamp_ns=m.now_ns(), target_state=m.PresenceTarget.STANDING,
        presence_state=m.PresenceState.IN_RANGE, distance_m=1.0))
    _raw_ros2(tmp_path / "cut.mcap", ros_type, "/radar_presence", payload[:-5],
              rosbag.message_definition(ros_type).encode())
    assert run("import", str(tmp_path / "cut.mcap"), str(tmp_path / "o.mcap")) == 0
    err = capsys.readouterr().err
    assert "1 messages on /radar_presence refused (first: " in err
    assert "imported 0 messages" in err and "nothing imported" in err
    assert bag.read_info(tmp_path / "o.mcap").messages == 0


def test_a_schema_other_than_ours_skips_its_topic(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    ros_type, payload = convert.to_ros(m.PupilControl(stamp_ns=m.now_ns(),
                                                      dilation_percentage=10))
    _raw_ros2(tmp_path / "ros2.mcap", ros_type, "/pupil_control", payload,
              b"uint64 stamp_ns\nfloat32 dilation_percentage\n")
    assert run("import", str(tmp_path / "ros2.mcap"), str(tmp_path / "o.mcap")) == 0
    assert ("skipping /pupil_control: a schema that gives buddybot_interfaces/msg/PupilControl "
            "other field types than ours") in capsys.readouterr().err


def test_a_declared_gibibyte_chunk_is_refused_and_nothing_is_left(tmp_path: Path) -> None:
    write_bomb(tmp_path / "bomb.mcap", 1 << 30)
    with pytest.raises(bag.BagError, match=r"refused: a chunk of .* over the limit"):
        run("import", str(tmp_path / "bomb.mcap"), str(tmp_path / "o.mcap"))
    assert not (tmp_path / "o.mcap").exists()


def test_a_truncated_file_and_a_damaged_recording_are_refused(
        recording: tuple[Path, dict[str, tuple[keys.Topic, bytes]], int],
        tmp_path: Path) -> None:
    path, _found, _base = recording
    data = path.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(bag.BagError, match="truncated"):
        run("import", str(tmp_path / "cut.mcap"), str(tmp_path / "o.mcap"))
    with pytest.raises(bag.BagError, match="truncated"):
        run("export", "--ros2", str(tmp_path / "cut.mcap"), str(tmp_path / "out"))
    assert not (tmp_path / "out").exists()
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "mine").write_text("x")
    with pytest.raises(bag.BagError, match="not an empty directory"):
        run("export", "--ros2", str(path), str(tmp_path / "taken"))


def test_export_needs_its_format() -> None:
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args(["bag", "export", "in.mcap", "out"])


def _pixels(image: m.Image) -> bytes:
    """The bgr8 pixels OpenCV decodes from a JPEG frame (what a raw Image holds)."""
    import cv2

    bgr = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
    return bytes(bgr.tobytes())


def _raw_images(directory: Path) -> list[tuple[str, Any]]:
    """(schema name, decoded message) of every /raw_image message, read by
    mcap-ros2-support."""
    with open(directory / f"{directory.name}_0.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [(schema.name, ros) for schema, channel, _r, ros
                in reader.iter_decoded_messages(topics=["/raw_image"]) if schema is not None]


def test_raw_image_in_a_bag_is_the_live_type_for_the_same_settings(
        recording: tuple[Path, dict[str, tuple[keys.Topic, bytes]], int],
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`[ros2] raw_image` decides /raw_image's type in a bag as it does live
    (`--raw-image` on top), and `bag import` takes both back."""
    path, _found, _base = recording
    frame = next(channels.decode(i.topic, i.payload) for i in bag.open_recording(path).messages()
                 if i.topic is keys.CAMERA_IMAGE)  # as recorded: JPEG
    compressed = parse_config('[ros2]\nraw_image = "compressed"\n')
    assert run("export", "--ros2", str(path), str(tmp_path / "small"), config=compressed) == 0
    assert run("export", "--ros2", str(path), str(tmp_path / "big"), "--raw-image", "raw",
               config=compressed) == 0
    assert run("export", "--ros2", str(path), str(tmp_path / "plain")) == 0
    capsys.readouterr()
    for name, setting in (("small", "compressed"), ("big", "raw"), ("plain", "raw")):
        live = {o.name: o for o in bridge.outgoing(Ros2Settings(raw_image=setting))}
        ((schema, ros),) = _raw_images(tmp_path / name)
        assert schema == live["raw_image"].ros_type, name
        if schema == types.IMAGE:
            assert (ros.encoding, ros.width, ros.height) == ("bgr8", frame.width, frame.height)
            assert bytes(ros.data) == _pixels(frame)
        else:
            assert (ros.format, bytes(ros.data)) == ("jpeg", frame.data)
    for name in ("small", "big"):
        assert run("import", str(tmp_path / name), str(tmp_path / f"{name}.mcap")) == 0
        back = [channels.decode(i.topic, i.payload)
                for i in bag.open_recording(tmp_path / f"{name}.mcap").messages()
                if i.topic is keys.CAMERA_IMAGE]
        assert [(b.width, b.height, b.stamp_ns, b.frame_id) for b in back] == [
            (frame.width, frame.height, frame.stamp_ns, frame.frame_id)], name
    assert "imported 11 messages from 11 ROS 2 topics" in capsys.readouterr().err
