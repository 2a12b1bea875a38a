"""Which of our keys the ROS 2 bridge maps to which ROS 2 topic, and how (pure).

Two tables, the bridge's whole contract with ROS 2:

* `OUTGOING`: a message on one of our keys -> a sample on a ROS 2 topic
  (the original ROS 2 names and types): `camera/{camera}/face` ->
  `/face_position` (geometry_msgs/msg/PointStamped), the camera's frames ->
  `/raw_image` (Image, or CompressedImage with `[ros2] raw_image =
  "compressed"`: `outgoing`), `/debug_image`, `/ld2410_target_frames`,
  `/ld2450_targets` (geometry_msgs/msg/PoseArray), `/radar_presence`, the
  eye topics (buddybot_interfaces) and `/audio_device_is_free`
  (std_msgs/msg/Bool);
* `INCOMING`: a sample of a ROS 2 node -> a request to the robot:
  `/screen_expression` and `/eye_control` -> the controller (a lease on
  `expression` or `gaze`, then `eyes/command`), never our keys directly
  (the controller alone publishes the eyes).

Each outgoing entry carries the QoS its graph token announces (latched
keys transient-local depth 1, images best effort depth 5, the rest
rmw_zenoh's default), also what an exported bag offers (rosbag.py: a bag
replays as the bridge ran); images are `on_demand`, taken only while a
ROS 2 subscription to the topic is in the graph (service.py). `Route`
spells an entry's topic name and key expression; `split_key` reads the
type and hash back from a peer's key, so a wrong one is counted.
The whole table and the QoS, why: docs/ros2.md, 'The bridge service'.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import convert, types, wire
from buddybot.ros2.settings import Ros2Settings

NODE_NAME = "buddybot_bridge"
"""The ROS 2 node name the bridge's graph tokens carry (`ros2 node list`)."""
EXPRESSION = f"{types.OURS}/msg/ScreenExpression"
PRESENCE = f"{types.OURS}/msg/PresenceDetection"
EYE_CONTROL = f"{types.OURS}/msg/EyeControl"

DEFAULT_QOS = wire.Qos(depth=10)
"""rmw_zenoh's default profile with depth 10 (reliable, volatile, keep last)."""
LATCHED_QOS = wire.Qos(durability=wire.TRANSIENT_LOCAL, depth=1)
"""Reliable, transient-local, depth 1: a late ROS 2 subscriber gets the last value."""
SENSOR_QOS = wire.Qos(reliability=wire.BEST_EFFORT, depth=5)
"""ROS's sensor-data profile (best effort, volatile, depth 5) for images."""


def cache(qos: wire.Qos) -> int | None:
    """Samples a publisher of `qos` keeps for late joiners: its depth when it is
    transient local (as rmw_zenoh's advanced publishers do), None when volatile."""
    return qos.depth if qos.durability == wire.TRANSIENT_LOCAL else None


def _ours(message: Any) -> bytes:
    return convert.to_ros(message)[1]


@dataclass(frozen=True)
class Outgoing:
    """Our topic `topic` published to ROS 2 as `name` (relative to the namespace).

    `on_demand`: our key is subscribed only while a ROS 2 subscription to the
    topic exists (images: large, and the debug image is drawn only while
    someone subscribes to it)."""

    topic: keys.Topic
    name: str
    ros_type: str
    encode: Callable[[Any], bytes]
    qos: wire.Qos = DEFAULT_QOS
    on_demand: bool = False

    @property
    def latched(self) -> bool:
        return cache(self.qos) is not None


@dataclass(frozen=True)
class Incoming:
    """ROS 2 topic `name` (relative to the namespace) taken in as `decode`'s message,
    asking the controller for a lease on `resource`. `latest`: only the newest
    waiting sample matters (a gaze stream), else they are taken in order."""

    name: str
    ros_type: str
    decode: Callable[[bytes], m.Message]
    resource: m.Resource
    latest: bool = False


RAW_IMAGE = Outgoing(keys.CAMERA_IMAGE, "raw_image", types.IMAGE, convert.raw_image_to_ros,
                     SENSOR_QOS, on_demand=True)
RAW_IMAGE_COMPRESSED = Outgoing(keys.CAMERA_IMAGE, "raw_image", types.COMPRESSED_IMAGE,
                                convert.compressed_image_to_ros, SENSOR_QOS, on_demand=True)
"""`/raw_image` with `[ros2] raw_image = "compressed"`: JPEG, about a tenth of the bytes."""

OUTGOING: tuple[Outgoing, ...] = (
    Outgoing(keys.FACE, "face_position", types.POINT_STAMPED, convert.face_to_ros),
    RAW_IMAGE,
    Outgoing(keys.DEBUG_IMAGE, "debug_image", types.COMPRESSED_IMAGE,
             convert.compressed_image_to_ros, SENSOR_QOS, on_demand=True),
    Outgoing(keys.RADAR_FRAMES, "ld2410_target_frames",
             f"{types.OURS}/msg/LD2410TargetDataFrameArray", _ours),
    Outgoing(keys.RADAR_TARGETS, "ld2450_targets", types.POSE_ARRAY,
             convert.radar_targets_to_ros),
    Outgoing(keys.PRESENCE, "radar_presence", PRESENCE, _ours, LATCHED_QOS),
    Outgoing(keys.EXPRESSION, "screen_expression", EXPRESSION, _ours, LATCHED_QOS),
    Outgoing(keys.EYE_CONTROL, "eye_control", EYE_CONTROL, _ours),
    Outgoing(keys.EYES_DIRECTION, "eyes_direction_control",
             f"{types.OURS}/msg/EyesDirection", _ours),
    Outgoing(keys.PUPIL, "pupil_control", f"{types.OURS}/msg/PupilControl", _ours),
    Outgoing(keys.LIDS, "eye_lid_control", f"{types.OURS}/msg/EyeLidControl", _ours,
             LATCHED_QOS),
    Outgoing(keys.DEVICE_FREE, "audio_device_is_free", types.BOOL, convert.bool_to_ros,
             LATCHED_QOS),
)
"""The default table (`/raw_image` as sensor_msgs/msg/Image); `outgoing` applies the settings."""


def outgoing(settings: Ros2Settings) -> tuple[Outgoing, ...]:
    """`OUTGOING` as the settings ask: `/raw_image` compressed or not."""
    if settings.raw_image == "compressed":
        return tuple(RAW_IMAGE_COMPRESSED if o is RAW_IMAGE else o for o in OUTGOING)
    return OUTGOING


def _expression(payload: bytes) -> m.Message:
    return convert.from_ros(payload, m.ScreenExpression)


def _eye_control(payload: bytes) -> m.Message:
    return convert.from_ros(payload, m.EyeControl)


INCOMING: tuple[Incoming, ...] = (
    Incoming("screen_expression", EXPRESSION, _expression, "expression"),
    Incoming("eye_control", EYE_CONTROL, _eye_control, "gaze", latest=True),
)


def fully_qualified(namespace: str, name: str) -> str:
    """`/face_position` in namespace `/`, `/robot1/face_position` in `/robot1`."""
    return f"{namespace.rstrip('/')}/{name}"


@dataclass(frozen=True)
class Route:
    """One table entry placed in a domain and namespace."""

    ros_name: str
    ros_type: str
    type_hash: str
    key: str
    """The rmw_zenoh key expression samples travel on."""

    @property
    def any_type_key(self) -> str:
        """The key expression of this topic under any type and hash (to count the wrong ones)."""
        return self.key.rsplit("/", 2)[0] + "/*/*"


def route(settings: Ros2Settings, name: str, ros_type: str) -> Route:
    ros_name = fully_qualified(settings.namespace, name)
    type_hash = types.type_hash(ros_type)
    return Route(ros_name, ros_type, type_hash,
                 wire.topic_key(settings.domain_id, ros_name, ros_type, type_hash))


def split_key(key: str) -> tuple[str, str]:
    """(DDS type name, type hash): the last two chunks of a data key."""
    parts = key.rsplit("/", 2)
    if len(parts) != 3:
        raise wire.WireError(f"not a ROS 2 data key: {key[:200]!r}")
    return parts[1], parts[2]
