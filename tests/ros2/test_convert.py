"""Our messages <-> CDR, checked against an implementation that is not ours.

The other implementation is mcap-ros2-support's dynamic CDR decoder and
encoder (`mcap_ros2._dynamic`: its own CDR reader/writer and its own copy of
rosidl's `.msg` parser). For our types it reads the checked-in `.msg` files
of ros2/buddybot_interfaces; for the standard ones the standard definitions.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from buddybot.contract import messages as m
from buddybot.ros2 import convert, interfaces, types
from buddybot.ros2.convert import ConvertError
from tests.properties import examples

MSG = interfaces.ROOT / "msg"
SEPARATOR = "=" * 80


def schema_of_ours(name: str, nested: tuple[str, ...] = ()) -> str:
    """mcap's schema text of one of our messages, from the checked-in files only."""
    text = (MSG / f"{name}.msg").read_text()
    for sub in nested:
        text += f"{SEPARATOR}\nMSG: {interfaces.PACKAGE}/{sub}\n" + (MSG / f"{sub}.msg").read_text()
    return text


STANDARD = {
    types.POINT_STAMPED: "std_msgs/Header header\ngeometry_msgs/Point point\n",
    types.IMAGE: ("std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
                  "uint8 is_bigendian\nuint32 step\nuint8[] data\n"),
    types.COMPRESSED_IMAGE: "std_msgs/Header header\nstring format\nuint8[] data\n",
    types.BOOL: "bool data\n",
    types.POSE_ARRAY: "std_msgs/Header header\ngeometry_msgs/Pose[] poses\n",
}
"""The standard definitions as ROS 2 Jazzy ships them (field lines only)."""
DEPENDENCIES = (f"{SEPARATOR}\nMSG: std_msgs/Header\n"
                "builtin_interfaces/Time stamp\nstring frame_id\n"
                f"{SEPARATOR}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
                f"{SEPARATOR}\nMSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n")
POSES = (f"{SEPARATOR}\nMSG: geometry_msgs/Pose\ngeometry_msgs/Point position\n"
         f"geometry_msgs/Quaternion orientation\n"
         f"{SEPARATOR}\nMSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\n"
         "float64 w\n")
"""geometry_msgs/msg/PoseArray's own dependencies (after DEPENDENCIES)."""


def their_decoder(ros_type: str, schema: str) -> Any:
    name = ros_type.replace("/msg/", "/")
    return generate_dynamic(name, schema)[name]


def their_encoder(ros_type: str, schema: str) -> Any:
    name = ros_type.replace("/msg/", "/")
    return serialize_dynamic(name, schema)[name]


FRAMES = m.LD2410TargetDataFrameArray(stamp_ns=1_700_000_000_000_000_000, device_id=3, sensors=[
    m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.MOVING_AND_STATIONARY,
                            movement_distance=65535, movement_energy=100, stationary_distance=87,
                            stationary_energy=40, detection_distance=90, max_moving_gate=8,
                            max_stationary_gate=8, moving_gate_energy=[0, 5, 100] * 3,
                            stationary_gate_energy=[7] * 9, light_level=255, out_pin=1),
    m.LD2410TargetDataFrame(radar_id=1, target_state=m.TargetState.NO_TARGET,
                            movement_distance=0, movement_energy=0, stationary_distance=0,
                            stationary_energy=0, detection_distance=0),
])
OURS = [
    FRAMES,
    m.PresenceDetection(stamp_ns=5, target_state=m.PresenceTarget.STANDING,
                        presence_state=m.PresenceState.IN_RANGE, distance_m=1.25),
    m.ScreenExpression(stamp_ns=6, action=m.ExpressionAction.ANIMATE_STAR),
    m.EyeControl(stamp_ns=7, yaw=-0.5, pitch=0.25, target_distance_cm=120.0),
    m.EyesDirection(stamp_ns=8, yaw=30.0, pitch=-10.0, target_distance_cm=80.5),
    m.EyesDirection(stamp_ns=8, yaw=30.0, pitch=-10.0),
    m.PupilControl(stamp_ns=9, dilation_percentage=62.5),
    m.EyeLidControl(stamp_ns=10, eye_id=m.EyeId.BOTH, top_lid_position=50.0,
                    bottom_lid_position=12.5),
]
FACE = m.FacePosition(stamp_ns=1_700_000_000_123_456_789, frame_id="camera_link",
                      point=m.Point(x=0.8, y=-0.1, z=0.05), confidence=1.0)


def _nested(msg: m.Message) -> tuple[str, ...]:
    return ("LD2410TargetDataFrame",) if isinstance(msg, m.LD2410TargetDataFrameArray) else ()


@pytest.mark.parametrize("msg", OURS, ids=lambda msg: type(msg).__name__)
def test_our_messages_round_trip(msg: m.Message) -> None:
    ros_type, payload = convert.to_ros(msg)
    assert ros_type == f"buddybot_interfaces/msg/{type(msg).__name__}"
    assert convert.from_ros(payload, type(msg)) == msg


@pytest.mark.parametrize("msg", OURS, ids=lambda msg: type(msg).__name__)
def test_their_decoder_reads_our_bytes(msg: m.Message) -> None:
    ros_type, payload = convert.to_ros(msg)
    decoded = their_decoder(ros_type, schema_of_ours(type(msg).__name__, _nested(msg)))(payload)
    if isinstance(msg, m.LD2410TargetDataFrameArray):
        first, second = decoded.sensors
        assert (decoded.stamp_ns, decoded.device_id) == (msg.stamp_ns, 3)
        assert (first.movement_distance, first.target_state, first.light_level) == \
            (65535, 3, b"\xff")
        assert list(first.moving_gate_energy) == [0, 5, 100] * 3
        assert (second.max_moving_gate, list(second.moving_gate_energy)) == (b"", [])
    else:
        for name in msg.__struct_fields__:
            value, theirs = getattr(msg, name), getattr(decoded, name)
            if value is None:
                assert len(theirs) == 0
            elif name == "target_distance_cm" and isinstance(msg, m.EyesDirection):
                assert list(theirs) == [value]
            else:
                assert theirs == value, name


@pytest.mark.parametrize("msg", OURS, ids=lambda msg: type(msg).__name__)
def test_we_read_their_encoders_bytes(msg: m.Message) -> None:
    ros_type, ours = convert.to_ros(msg)
    schema = schema_of_ours(type(msg).__name__, _nested(msg))
    decoded = their_decoder(ros_type, schema)(ours)
    theirs = their_encoder(ros_type, schema)(decoded)
    assert convert.from_ros(theirs, type(msg)) == msg


def test_a_face_is_a_point_stamped_for_them() -> None:
    payload = convert.face_to_ros(FACE)
    decoded = their_decoder(types.POINT_STAMPED, STANDARD[types.POINT_STAMPED] + DEPENDENCIES)(
        payload)
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert decoded.header.frame_id == "camera_link"
    assert (decoded.point.x, decoded.point.y, decoded.point.z) == (0.8, -0.1, 0.05)
    assert convert.face_from_ros(payload) == FACE


def test_their_point_stamped_becomes_our_face() -> None:
    encode = their_encoder(types.POINT_STAMPED, STANDARD[types.POINT_STAMPED] + DEPENDENCIES)
    payload = encode({"header": {"stamp": {"sec": 12, "nanosec": 5}, "frame_id": "cam"},
                      "point": {"x": 1.0, "y": 2.0, "z": 3.0}})
    face = convert.face_from_ros(payload, confidence=0.5)
    assert face == m.FacePosition(stamp_ns=12_000_000_005, frame_id="cam",
                                  point=m.Point(x=1.0, y=2.0, z=3.0), confidence=0.5)


def test_a_bgr8_image_both_ways() -> None:
    pixels = np.arange(4 * 3 * 3, dtype=np.uint8).tobytes()
    image = m.Image(stamp_ns=2_000_000_001, frame_id="cam", width=4, height=3, encoding="bgr8",
                    data=pixels)
    ros_type, payload = convert.image_to_ros(image)
    assert ros_type == types.IMAGE
    schema = STANDARD[types.IMAGE] + DEPENDENCIES
    decoded = their_decoder(ros_type, schema)(payload)
    assert (decoded.width, decoded.height, decoded.step, decoded.encoding) == (4, 3, 12, "bgr8")
    assert bytes(decoded.data) == pixels
    assert convert.image_from_ros(their_encoder(ros_type, schema)(decoded), ros_type) == image


def test_a_jpeg_image_is_a_compressed_image() -> None:
    data = Path(__file__).resolve().parents[2] / "services" / "camera" / "data"
    jpeg = next((p.read_bytes() for p in sorted(data.glob("*.jp*g"))), None)
    if jpeg is None:
        import cv2
        ok, buf = cv2.imencode(".jpg", np.zeros((6, 10, 3), np.uint8))
        assert ok
        jpeg = buf.tobytes()
    from buddybot.contract import jpeg as jpeg_header
    header = jpeg_header.read_header(jpeg)
    image = m.Image(stamp_ns=1, frame_id="cam", width=header.width, height=header.height,
                    encoding="jpeg", data=jpeg)
    ros_type, payload = convert.image_to_ros(image)
    assert ros_type == types.COMPRESSED_IMAGE
    decoded = their_decoder(ros_type, STANDARD[ros_type] + DEPENDENCIES)(payload)
    assert (decoded.format, bytes(decoded.data)) == ("jpeg", jpeg)
    assert convert.image_from_ros(payload, ros_type) == image


@pytest.mark.parametrize("frame_id", ["", "c", "ca", "cam", "front", "camera_link_12"])
@pytest.mark.parametrize("encoding", ["bgr8", "jpeg"])
def test_image_bytes_equal_rosbags(frame_id: str, encoding: str) -> None:
    """The images' own CDR writer (no rosbags: speed) writes rosbags' bytes,
    whatever padding the frame id's length asks for."""
    image = m.Image(stamp_ns=3_000_000_007, frame_id=frame_id, width=2,
                    height=1, encoding=encoding,  # type: ignore[arg-type]
                    data=bytes(range(6)) if encoding == "bgr8" else b"\xff\xd8jpeg")
    ros_type, payload = convert.image_to_ros(image)
    store = types.typestore()
    header = store.types["std_msgs/msg/Header"](
        stamp=store.types["builtin_interfaces/msg/Time"](sec=3, nanosec=7), frame_id=frame_id)
    data = np.frombuffer(image.data, dtype=np.uint8)
    if encoding == "bgr8":
        msg = store.types[types.IMAGE](header=header, height=1, width=2, encoding="bgr8",
                                       is_bigendian=0, step=6, data=data)
    else:
        msg = store.types[types.COMPRESSED_IMAGE](header=header, format="jpeg", data=data)
    assert payload == convert.serialize(msg, ros_type)


def test_bool_both_ways() -> None:
    payload = convert.bool_to_ros(m.Bool(stamp_ns=1, data=True))
    assert their_decoder(types.BOOL, STANDARD[types.BOOL])(payload).data is True
    theirs = their_encoder(types.BOOL, STANDARD[types.BOOL])({"data": False})
    assert convert.bool_from_ros(theirs, stamp_ns=42) == m.Bool(stamp_ns=42, data=False)


# --- what is refused -----------------------------------------------------------------


def _expression(action: int) -> bytes:
    return convert.to_ros(m.ScreenExpression(stamp_ns=1, action=m.ExpressionAction(action)))[1]


def _string_with_length(claimed: int) -> bytes:
    """A Bool-free PointStamped whose frame_id claims `claimed` bytes."""
    payload = bytearray(convert.face_to_ros(FACE))
    struct.pack_into("<I", payload, 4 + 8, claimed)
    return bytes(payload)


@pytest.mark.parametrize(("payload", "reason"), [
    (b"", "encapsulation"),
    (b"\x00\x01\x00", "encapsulation"),
    (b"\x00\x07\x00\x00" + bytes(16), "encapsulation"),
    (convert.face_to_ros(FACE)[:20], "string length"),
    (convert.face_to_ros(FACE) + bytes(8), "size"),
    (_string_with_length(0xFFFF_FFFF), None),
    (_string_with_length(40), None),
    (convert.bool_to_ros(m.Bool(stamp_ns=1, data=True)), None),  # another type's bytes
    (bytes(convert.MAX_PAYLOAD + 1), "limit"),
], ids=["empty", "short-header", "not-cdr", "cut", "trailing", "string-4G", "string-long",
        "other-type", "oversize"])
def test_malformed_point_stamped_is_refused(payload: bytes, reason: str | None) -> None:
    with pytest.raises(ConvertError, match=reason):
        convert.face_from_ros(payload)


def test_an_absurd_array_length_is_refused() -> None:
    image = m.Image(stamp_ns=1, frame_id="c", width=1, height=1, encoding="bgr8", data=bytes(3))
    ros_type, payload = convert.image_to_ros(image)
    bad = bytearray(payload)
    struct.pack_into("<I", bad, len(bad) - 3 - 4, 0x7FFF_FFFF)
    with pytest.raises(ConvertError):
        convert.image_from_ros(bytes(bad), ros_type)


def test_values_outside_the_contract_are_refused() -> None:
    with pytest.raises(ConvertError, match="action"):
        convert.from_ros(_expression(3)[:-1] + b"\x63", m.ScreenExpression)
    pupil = bytearray(convert.to_ros(m.PupilControl(stamp_ns=1, dilation_percentage=1.0))[1])
    struct.pack_into("<d", pupil, len(pupil) - 8, float("nan"))
    with pytest.raises(ConvertError, match="dilation_percentage"):
        convert.from_ros(bytes(pupil), m.PupilControl)


def test_an_optional_with_two_values_is_refused() -> None:
    """`float64[<=1]` holding two values (their encoder refuses to write it, so by hand)."""
    one = convert.to_ros(m.EyesDirection(stamp_ns=1, yaw=0.0, pitch=0.0,
                                         target_distance_cm=1.0))[1]
    payload = bytearray(one + struct.pack("<d", 2.0))
    struct.pack_into("<I", payload, 4 + 24, 2)
    with pytest.raises(ConvertError, match="2 values"):
        convert.from_ros(payload, m.EyesDirection)


def test_an_image_that_is_not_what_it_says_is_refused() -> None:
    schema = STANDARD[types.IMAGE] + DEPENDENCIES
    encode = their_encoder(types.IMAGE, schema)
    header = {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "c"}
    wrong = [
        ({"encoding": "rgb8", "step": 6, "data": bytes(6)}, "encoding"),
        ({"encoding": "bgr8", "step": 6, "data": bytes(5)}, "bytes"),
        ({"encoding": "bgr8", "step": 7, "data": bytes(7)}, "step"),
    ]
    for fields, reason in wrong:
        payload = encode({"header": header, "height": 1, "width": 2, "is_bigendian": 0, **fields})
        with pytest.raises(ConvertError, match=reason):
            convert.image_from_ros(payload, types.IMAGE)
    compressed = their_encoder(types.COMPRESSED_IMAGE, STANDARD[types.COMPRESSED_IMAGE]
                               + DEPENDENCIES)
    with pytest.raises(ConvertError, match="format"):
        convert.image_from_ros(compressed({"header": header, "format": "png", "data": b"x"}),
                               types.COMPRESSED_IMAGE)
    with pytest.raises(ConvertError):
        convert.image_from_ros(compressed({"header": header, "format": "jpeg", "data": b"junk"}),
                               types.COMPRESSED_IMAGE)


def test_a_message_without_an_interface_is_refused() -> None:
    with pytest.raises(ConvertError, match="Bool"):
        convert.to_ros(m.Bool(stamp_ns=1, data=True))
    with pytest.raises(ConvertError, match="Bool"):
        convert.from_ros(b"", m.Bool)


@pytest.mark.parametrize("msg", OURS, ids=lambda msg: type(msg).__name__)
def test_every_one_of_our_types_refuses_short_and_padded_cdr(msg: m.Message) -> None:
    _, payload = convert.to_ros(msg)
    for cut in (4, len(payload) // 2, len(payload) - 1):
        with pytest.raises(ConvertError):
            convert.from_ros(payload[:cut], type(msg))
    with pytest.raises(ConvertError):
        convert.from_ros(payload + bytes(8), type(msg))


def test_an_absurd_count_of_radar_frames_is_refused() -> None:
    """`sensors` claims 4 G, 2 G, then 3 frames where the payload holds 2."""
    _, payload = convert.to_ros(FRAMES)
    offset = 4 + 8 + 8  # the CDR header, stamp_ns, device_id
    assert struct.unpack_from("<I", payload, offset) == (2,)
    for claimed in (0xFFFF_FFFF, 0x7FFF_FFFF, 3):
        bad = bytearray(payload)
        struct.pack_into("<I", bad, offset, claimed)
        with pytest.raises(ConvertError):
            convert.from_ros(bytes(bad), m.LD2410TargetDataFrameArray)


def test_a_bgr8_frame_becomes_a_compressed_image_they_can_read() -> None:
    import cv2

    pixels = np.full((6, 10, 3), (10, 200, 30), np.uint8)
    image = m.Image(stamp_ns=3_000_000_004, frame_id="front", width=10, height=6,
                    encoding="bgr8", data=pixels.tobytes())
    payload = convert.compressed_image_to_ros(image)
    decoded = their_decoder(types.COMPRESSED_IMAGE,
                            STANDARD[types.COMPRESSED_IMAGE] + DEPENDENCIES)(payload)
    assert decoded.format == "jpeg" and decoded.header.frame_id == "front"
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (3, 4)
    back = cv2.imdecode(np.frombuffer(bytes(decoded.data), np.uint8), cv2.IMREAD_COLOR)
    assert back.shape == (6, 10, 3)
    assert np.abs(back.astype(int) - pixels.astype(int)).max() < 16
    jpeg_image = convert.image_from_ros(payload, types.COMPRESSED_IMAGE)
    assert convert.compressed_image_to_ros(jpeg_image) == payload  # JPEG passes as it is


def test_raw_image_refuses_a_jpeg_that_does_not_decode_and_checks_the_pixels() -> None:
    jpeg_image = m.Image(stamp_ns=1, frame_id="c", width=1, height=1, encoding="jpeg",
                         data=b"\xff\xd8")
    with pytest.raises(ConvertError, match="jpeg frame that does not decode"):
        convert.raw_image_to_ros(jpeg_image)
    short = m.Image(stamp_ns=1, frame_id="c", width=4, height=4, encoding="bgr8", data=bytes(5))
    with pytest.raises(ConvertError):
        convert.compressed_image_to_ros(short)


def test_raw_image_decodes_a_jpeg_frame_to_its_pixels() -> None:
    """A camera set to `jpeg` (and every recorded frame) still gives /raw_image an
    Image: the pixels OpenCV decodes, the header's stamp and frame id."""
    import cv2

    pixels = np.zeros((6, 10, 3), np.uint8)
    pixels[:, 5:] = (200, 40, 10)
    ok, buf = cv2.imencode(".jpg", pixels)
    assert ok
    image = m.Image(stamp_ns=4_000_000_009, frame_id="front", width=10, height=6,
                    encoding="jpeg", data=buf.tobytes())
    decoded = their_decoder(types.IMAGE, STANDARD[types.IMAGE] + DEPENDENCIES)(
        convert.raw_image_to_ros(image))
    assert (decoded.width, decoded.height, decoded.encoding, decoded.step) == (10, 6, "bgr8", 30)
    assert (decoded.header.frame_id, decoded.header.stamp.nanosec) == ("front", 9)
    expected = cv2.imdecode(np.frombuffer(buf, np.uint8), cv2.IMREAD_COLOR)
    assert bytes(decoded.data) == expected.tobytes()
    liar = msgspec.structs.replace(image, width=20)  # the header says 10x6
    with pytest.raises(ConvertError, match="does not decode: jpeg header says 10x6"):
        convert.raw_image_to_ros(liar)


SENSOR_M = st.floats(-32.768, 32.768, allow_nan=False)


@st.composite
def radar_targets(draw: st.DrawFn) -> m.RadarTargets:
    targets = [m.RadarTarget(slot=slot, x_m=draw(SENSOR_M), y_m=draw(SENSOR_M), speed_mps=-0.2,
                             resolution_m=0.32, position=m.Point(x=0.0, y=0.0, z=0.0),
                             bearing_rad=0.0, distance_m=0.0)
               for slot in range(draw(st.integers(0, m.MAX_RADAR_TARGETS)))]
    return m.RadarTargets(stamp_ns=draw(st.integers(0, 2**31 * 10**9 - 1)),
                          device_id=draw(st.integers(0, 65535)),
                          radar_id=draw(st.integers(0, 255)), targets=targets)


@settings(max_examples=examples(80))
@given(radar_targets())
def test_radar_targets_are_a_pose_array_in_the_radars_frame(report: m.RadarTargets) -> None:
    """One pose per target, in the radar's own frame with ROS axes (forward =
    the datasheet's y, left = -x), z 0 and the frame's orientation; read by
    mcap-ros2-support from the standard definition."""
    decoded = their_decoder(types.POSE_ARRAY, STANDARD[types.POSE_ARRAY] + DEPENDENCIES + POSES)(
        convert.radar_targets_to_ros(report))
    assert decoded.header.frame_id == f"radar_{report.device_id}_{report.radar_id}"
    assert (decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec) == report.stamp_ns
    assert [(p.position.x, p.position.y, p.position.z) for p in decoded.poses] == [
        (t.y_m, -t.x_m, 0.0) for t in report.targets]
    assert all((p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)
               == (0.0, 0.0, 0.0, 1.0) for p in decoded.poses)


ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)
OFFSET = st.floats(-10.0, 10.0, allow_nan=False)


@settings(max_examples=examples(200))
@given(x_m=SENSOR_M, y_m=SENSOR_M, x=OFFSET, y=OFFSET, z=OFFSET, yaw=ANGLE,
       mirror_x=st.booleans())
def test_the_documented_static_tf_places_a_pose_where_the_radar_places_it(
        x_m: float, y_m: float, x: float, y: float, z: float, yaw: float,
        mirror_x: bool) -> None:
    """docs/ros2.md's TF from the camera to `radar_<device>_<radar_id>` (the
    mount's x, y, z, yaw; roll pi when mirror_x) applied to the pose gives the
    point the radar bridge computes in the camera's frame (radar/mounting.py)."""
    from buddybot.radar.mounting import Mount, place

    forward, left = convert.radar_point(m.RadarTarget(
        slot=0, x_m=x_m, y_m=y_m, speed_mps=0.0, resolution_m=0.0,
        position=m.Point(x=0.0, y=0.0, z=0.0), bearing_rad=0.0, distance_m=0.0))
    roll = math.pi if mirror_x else 0.0
    # static_transform_publisher's rotation: R = Rz(yaw) Ry(0) Rx(roll)
    ry, rz = left * math.cos(roll), left * math.sin(roll)
    px = x + math.cos(yaw) * forward - math.sin(yaw) * ry
    py = y + math.sin(yaw) * forward + math.cos(yaw) * ry
    pz = z + rz
    placed = place(x_m, y_m, Mount(x=x, y=y, z=z, yaw=yaw, mirror_x=mirror_x))
    assert px == pytest.approx(placed.x, abs=1e-9)
    assert py == pytest.approx(placed.y, abs=1e-9)
    assert pz == pytest.approx(placed.z, abs=1e-9)
