"""Our messages <-> ROS 2 CDR payloads, with bounds on everything that comes in.

Outgoing (our message -> CDR): `FacePosition` -> geometry_msgs/msg/PointStamped
(header.stamp from `stamp_ns`, header.frame_id from `frame_id`; the
confidence has no field there), `Image` -> sensor_msgs/msg/Image (`bgr8`)
or sensor_msgs/msg/CompressedImage (`jpeg`), `RadarTargets` ->
geometry_msgs/msg/PoseArray in the radar's frame, `Bool` -> std_msgs/msg/Bool,
and every message of `interfaces.MESSAGES` -> its `buddybot_interfaces`
twin (same field names; an optional value is a sequence of at most one).

Incoming (CDR -> our message), never decoded unchecked: a payload larger
than its type's limit, without a plain CDR header, short, with a string or
sequence length beyond the payload, or with bytes left over is refused
before anything reaches our types (`deserialize`); the decoded values then pass the
contract's own checks (ranges, enums, string lengths) through
`msgspec.convert`. Every refusal is a `ConvertError` that says why.
"""

from __future__ import annotations

import functools
import struct
from typing import Any, Literal, TypeVar

import msgspec
import numpy as np
from msgspec import inspect as mi
from rosbags.serde import SerdeError

from buddybot.contract import jpeg
from buddybot.contract import messages as m
from buddybot.ros2 import interfaces, types, wire

MAX_IMAGE_PAYLOAD = m.MAX_SIDE * m.MAX_SIDE * 3 + 4096
"""Largest image payload taken in (the contract's largest bgr8 frame)."""
MAX_PAYLOAD = 1 << 20
"""Largest payload of any other type taken in (1 MiB)."""
JPEG_QUALITY = 80
"""Quality of a bgr8 frame compressed for a CompressedImage."""

OURS: dict[type[m.Message], str] = {
    cls: f"{types.OURS}/msg/{cls.__name__}" for cls in interfaces.MESSAGES}


M = TypeVar("M", bound=m.Message)


class ConvertError(ValueError):
    """A payload or message that cannot cross the bridge; the message says why."""


# --- CDR with bounds ---------------------------------------------------------


def serialize(message: object, ros_type: str) -> bytes:
    """CDR (little-endian, with its header) of a rosbags message object."""
    return bytes(types.typestore().serialize_cdr(message, ros_type))


def deserialize(payload: bytes | memoryview, ros_type: str) -> Any:
    """A rosbags message object from `payload`, checked: the type's size limit
    first, the plain-CDR header, then rosbags' deserializer, which refuses a
    string or sequence length beyond the payload (tests/ros2/test_convert.py
    holds it to that) and more than 3 bytes (CDR alignment) left over; whatever it
    raises becomes a `ConvertError`."""
    limit = MAX_IMAGE_PAYLOAD if ros_type in (types.IMAGE, types.COMPRESSED_IMAGE) \
        else MAX_PAYLOAD
    if len(payload) > limit:
        raise ConvertError(f"{ros_type}: payload of {len(payload)} bytes (limit {limit})")
    try:
        wire.encapsulation(payload)
        return types.typestore().deserialize_cdr(payload, ros_type)
    except (wire.WireError, SerdeError) as exc:
        raise ConvertError(f"{ros_type}: {exc}") from exc
    except (IndexError, KeyError, TypeError, OverflowError, MemoryError) as exc:
        raise ConvertError(f"{ros_type}: malformed CDR ({type(exc).__name__}: {exc})") from exc


# --- stamps and headers --------------------------------------------------------


def _time(stamp_ns: int) -> Any:
    cls = types.typestore().types["builtin_interfaces/msg/Time"]
    return cls(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)


def header(stamp_ns: int, frame_id: str) -> Any:
    cls = types.typestore().types["std_msgs/msg/Header"]
    return cls(stamp=_time(stamp_ns), frame_id=frame_id)


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _checked(cls: type[M], fields: dict[str, Any], ros_type: str) -> M:
    try:
        return msgspec.convert(fields, cls)
    except msgspec.ValidationError as exc:
        raise ConvertError(f"{ros_type} -> {cls.__name__}: {exc}") from exc


# --- standard types ---------------------------------------------------------------


def face_to_ros(face: m.FacePosition) -> bytes:
    """geometry_msgs/msg/PointStamped of a face (its confidence is not carried)."""
    store = types.typestore()
    point = store.types["geometry_msgs/msg/Point"](x=face.point.x, y=face.point.y,
                                                   z=face.point.z)
    msg = store.types[types.POINT_STAMPED](header=header(face.stamp_ns, face.frame_id),
                                           point=point)
    return serialize(msg, types.POINT_STAMPED)


def face_from_ros(payload: bytes | memoryview, confidence: float = 1.0) -> m.FacePosition:
    """A face from a PointStamped (which has no confidence: `confidence` is used)."""
    msg = deserialize(payload, types.POINT_STAMPED)
    return _checked(m.FacePosition, {
        "stamp_ns": _stamp_ns(msg.header), "frame_id": msg.header.frame_id,
        "point": {"x": msg.point.x, "y": msg.point.y, "z": msg.point.z},
        "confidence": confidence}, types.POINT_STAMPED)


class _Cdr:
    """Little-endian CDR (with its header) written as a list of parts joined once.

    The two image types are written here rather than by rosbags: its
    serializer allocates and fills a buffer of the whole frame and `serialize`
    copies it again, 1.2 ms per 640x480 frame, most of the bridge's CPU at 30
    fps; here the pixels are copied once, by the final join. Alignment counts
    from the end of the 4-byte encapsulation header, as CDR does
    (tests/ros2/test_convert.py holds the bytes equal to rosbags')."""

    def __init__(self) -> None:
        self.parts: list[bytes] = [wire.CDR_LE]
        self.offset = 0

    def _put(self, part: bytes) -> None:
        self.parts.append(part)
        self.offset += len(part)

    def _align(self, size: int) -> None:
        if pad := -self.offset % size:
            self._put(bytes(pad))

    def uint8(self, value: int) -> None:
        self._put(_UINT8.pack(value))

    def uint32(self, value: int) -> None:
        self._align(4)
        self._put(_UINT32.pack(value))

    def header(self, stamp_ns: int, frame_id: str) -> None:
        """std_msgs/msg/Header: stamp (int32 sec, uint32 nanosec), frame_id."""
        self._align(4)
        self._put(_TIME.pack(*divmod(stamp_ns, 1_000_000_000)))
        self.string(frame_id)

    def string(self, value: str) -> None:
        data = value.encode() + b"\0"
        self.uint32(len(data))
        self._put(data)

    def octets(self, data: bytes) -> None:
        """A `uint8[]`: its length, then the bytes (not copied before `payload`)."""
        self.uint32(len(data))
        self._put(data)

    def payload(self) -> bytes:
        return b"".join(self.parts)


_UINT8, _UINT32, _TIME = struct.Struct("<B"), struct.Struct("<I"), struct.Struct("<iI")


def image_to_ros(image: m.Image) -> tuple[str, bytes]:
    """(ROS type, payload): sensor_msgs/msg/Image for `bgr8`, CompressedImage for `jpeg`."""
    cdr = _Cdr()
    cdr.header(image.stamp_ns, image.frame_id)
    if image.encoding == "bgr8":
        cdr.uint32(image.height)
        cdr.uint32(image.width)
        cdr.string("bgr8")
        cdr.uint8(0)  # is_bigendian
        cdr.uint32(image.width * 3)  # step
        cdr.octets(image.data)
        return types.IMAGE, cdr.payload()
    cdr.string("jpeg")
    cdr.octets(image.data)
    return types.COMPRESSED_IMAGE, cdr.payload()


def raw_image_to_ros(image: m.Image) -> bytes:
    """sensor_msgs/msg/Image (`bgr8`) of a frame. A JPEG frame (a camera set to
    `jpeg`, every frame of a recording) is decoded first, so `/raw_image`
    has one type whatever the camera sends, live and in an exported bag."""
    if image.encoding != "bgr8":
        image = decoded_image(image)
    return image_to_ros(image)[1]


def decoded_image(image: m.Image) -> m.Image:
    """A JPEG frame as `bgr8`, its header checked against the message and the
    contract's largest frame before it is decoded (contract/images.py, which
    loads OpenCV: imported here, so a bridge fed bgr8 frames never loads it)."""
    from buddybot.contract import images

    try:
        bgr = images.decode_image(image, m.MAX_SIDE * m.MAX_SIDE)
    except images.FrameRefused as exc:
        raise ConvertError(f"a {image.encoding} frame that does not decode: {exc.text}"
                           ) from None
    return m.Image(stamp_ns=image.stamp_ns, frame_id=image.frame_id, width=image.width,
                   height=image.height, encoding="bgr8", data=bgr.tobytes())


def compressed_image_to_ros(image: m.Image) -> bytes:
    """sensor_msgs/msg/CompressedImage (`jpeg`): a JPEG frame as it is, a `bgr8`
    frame compressed at `JPEG_QUALITY`."""
    if image.encoding == "jpeg":
        return image_to_ros(image)[1]
    try:
        data = jpeg.from_image(image, JPEG_QUALITY)
    except jpeg.PixelsError as exc:
        raise ConvertError(str(exc)) from exc
    if data is None:
        raise ConvertError(f"a {image.width}x{image.height} frame did not compress")
    return image_to_ros(m.Image(stamp_ns=image.stamp_ns, frame_id=image.frame_id,
                                width=image.width, height=image.height, encoding="jpeg",
                                data=data))[1]


def image_from_ros(payload: bytes | memoryview, ros_type: str) -> m.Image:
    """Our image from a bgr8 sensor_msgs/msg/Image or a JPEG CompressedImage;
    any other encoding or format is refused."""
    msg = deserialize(payload, ros_type)
    stamp, frame_id = _stamp_ns(msg.header), msg.header.frame_id
    if ros_type == types.IMAGE:
        if msg.encoding != "bgr8":
            raise ConvertError(f"{ros_type}: encoding {msg.encoding[:32]!r} (only bgr8)")
        if msg.step != msg.width * 3 or len(msg.data) != msg.step * msg.height:
            raise ConvertError(f"{ros_type}: {len(msg.data)} bytes do not make a "
                               f"{msg.width}x{msg.height} bgr8 image with step {msg.step}")
        fields = {"width": msg.width, "height": msg.height, "encoding": "bgr8"}
    elif ros_type == types.COMPRESSED_IMAGE:
        if msg.format.split(";")[0].strip().lower() not in ("jpeg", "jpg", "bgr8"):
            raise ConvertError(f"{ros_type}: format {msg.format[:32]!r} (only jpeg)")
        try:
            header = jpeg.read_header(msg.data.tobytes())
        except jpeg.JpegError as exc:
            raise ConvertError(f"{ros_type}: {exc}") from exc
        fields = {"width": header.width, "height": header.height, "encoding": "jpeg"}
    else:
        raise ConvertError(f"{ros_type} is not an image type")
    return _checked(m.Image, {"stamp_ns": stamp, "frame_id": frame_id,
                              "data": msg.data.tobytes(), **fields}, ros_type)


def radar_frame(targets: m.RadarTargets) -> str:
    """The TF frame of one angle radar, `radar_<device_id>_<radar_id>`: a radar
    bridge may hold several sensors, each mounted on its own."""
    return f"radar_{targets.device_id}_{targets.radar_id}"


def radar_point(target: m.RadarTarget) -> tuple[float, float]:
    """(x forward, y left) in metres of a target in its sensor's own frame with
    ROS axes: the datasheet's y is forward, its +x the sensor's right (as
    radar/mounting.py reads it). The mount is left out on purpose: where the
    sensor sits is the TF from the robot to its frame (docs/ros2.md)."""
    return target.y_m, -target.x_m


def radar_targets_to_ros(targets: m.RadarTargets) -> bytes:
    """geometry_msgs/msg/PoseArray of one angle-radar report: the radar's frame,
    one pose per target (z 0), oriented as the frame (the LD2450 measures a
    radial speed, no heading); a report without targets has no pose (nobody)."""
    store = types.typestore()
    point, pose = store.types["geometry_msgs/msg/Point"], store.types["geometry_msgs/msg/Pose"]
    identity = store.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    poses = [pose(position=point(x=x, y=y, z=0.0), orientation=identity)
             for x, y in map(radar_point, targets.targets)]
    msg = store.types[types.POSE_ARRAY](header=header(targets.stamp_ns, radar_frame(targets)),
                                        poses=poses)
    return serialize(msg, types.POSE_ARRAY)


def bool_to_ros(value: m.Bool) -> bytes:
    return serialize(types.typestore().types[types.BOOL](data=value.data), types.BOOL)


def bool_from_ros(payload: bytes | memoryview, stamp_ns: int) -> m.Bool:
    """std_msgs/msg/Bool has no stamp: the arrival time `stamp_ns` is used."""
    msg = deserialize(payload, types.BOOL)
    return _checked(m.Bool, {"stamp_ns": stamp_ns, "data": bool(msg.data)}, types.BOOL)


# --- buddybot_interfaces -----------------------------------------------------------


@functools.cache
def _field_types(cls: type[m.Message]) -> dict[str, Any]:
    """Field name -> msgspec type of `cls`, read once per class (msgspec's
    inspection costs a millisecond, more than the CDR itself)."""
    info = mi.type_info(cls)
    assert isinstance(info, mi.StructType)
    return {f.name: f.type for f in info.fields}


def _bare(t: Any) -> Any:
    return t.type if isinstance(t, mi.Metadata) else t


def _optional(t: Any) -> Any | None:
    """The `X` of `X | None`, else None."""
    t = _bare(t)
    if isinstance(t, mi.UnionType):
        return next(x for x in t.types if not isinstance(x, mi.NoneType))
    return None


_DTYPES = {"uint8": np.uint8, "uint16": np.uint16, "uint32": np.uint32, "uint64": np.uint64,
           "int8": np.int8, "int16": np.int16, "int32": np.int32, "int64": np.int64,
           "float64": np.float64, "bool": np.bool_}


Optional = Literal["", "one", "list"]
"""How a field holds None on the ROS side: not optional, `X[<=1]`, or its empty list."""


@functools.cache
def _ros_fields(cls: type[m.Message]) -> tuple[tuple[str, str, Optional], ...]:
    """(name, ROS type, optional kind) of each field of `cls`, worked out once."""
    fields: list[tuple[str, str, Optional]] = []
    for name, t in _field_types(cls).items():
        inner = _optional(t)
        kind: Optional = "" if inner is None else (
            "list" if isinstance(_bare(inner), mi.ListType) else "one")
        fields.append((name, interfaces.ros_field(t, name).ros_type, kind))
    return tuple(fields)


def _to_ros(message: m.Message) -> Any:
    cls = type(message)
    values: dict[str, Any] = {}
    for name, ros_type, optional in _ros_fields(cls):
        value = getattr(message, name)
        if optional == "one":
            value = [] if value is None else [value]
        elif optional == "list":
            value = [] if value is None else value
        values[name] = _ros_value(value, ros_type)
    return types.typestore().types[OURS[cls]](**values)


def _ros_value(value: Any, ros_type: str) -> Any:
    if isinstance(value, m.Message):
        return _to_ros(value)
    if ros_type.endswith("]"):
        base = ros_type.split("[")[0]
        if base in _DTYPES:
            return np.array([int(v) if base != "float64" else v for v in value],
                            dtype=_DTYPES[base])
        return [_ros_value(v, base) for v in value]
    if isinstance(value, int) and not isinstance(value, bool):
        return int(value)
    return value


def to_ros(message: m.Message) -> tuple[str, bytes]:
    """(ROS type, CDR payload) of a message of `interfaces.MESSAGES`."""
    if type(message) not in OURS:
        raise ConvertError(f"{type(message).__name__} has no buddybot_interfaces type")
    return OURS[type(message)], serialize(_to_ros(message), OURS[type(message)])


def _from_ros(msg: Any, cls: type[m.Message]) -> dict[str, Any]:
    fields: dict[str, Any] = {}
    for name, t in _field_types(cls).items():
        fields[name] = _plain(getattr(msg, name), t)
    return fields


def _plain(value: Any, t: Any) -> Any:
    inner = _optional(t)
    if inner is not None:
        if isinstance(_bare(inner), mi.ListType):
            return _plain(value, inner) if len(value) else None
        if len(value) > 1:
            raise ConvertError(f"an optional value holds {len(value)} values")
        return _plain(value[0], inner) if len(value) else None
    bare = _bare(t)
    if isinstance(bare, mi.ListType):
        return [_plain(v, bare.item_type) for v in value]
    if isinstance(bare, mi.StructType) and issubclass(bare.cls, m.Message):
        return _from_ros(value, bare.cls)
    if isinstance(value, np.generic):
        return value.item()
    return value


def from_ros(payload: bytes | memoryview, cls: type[M]) -> M:
    """Our message `cls` (of `interfaces.MESSAGES`) from its CDR payload, checked."""
    if cls not in OURS:
        raise ConvertError(f"{cls.__name__} has no buddybot_interfaces type")
    msg = deserialize(payload, OURS[cls])
    return _checked(cls, _from_ros(msg, cls), OURS[cls])
