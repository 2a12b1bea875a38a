"""Which of our keys the ROS 2 bridge maps to which ROS 2 topic, and how (pure).

Two tables, the bridge's whole contract with ROS 2:

* `OUTGOING`: a message on one of our keys -> a sample on a ROS 2 topic
  (the seed's names and types): `camera/{camera}/face` -> `/face_position`
  (geometry_msgs/msg/PointStamped), `radar/presence` -> `/radar_presence`,
  `eyes/expression` -> `/screen_expression` (buddybot_interfaces),
  `audio/device_free` -> `/audio_device_is_free` (std_msgs/msg/Bool);
* `INCOMING`: a sample of a ROS 2 node -> a request to the robot:
  `/screen_expression` -> the controller (a lease, then `eyes/command`),
  never our keys directly (the controller alone publishes the eyes).

Topic names live in the settings' namespace and key expressions in their
domain (`Ros2Settings`); `Route` spells both for one entry, and
`split_key` reads the type and hash back from a key a peer published on,
so a sample of the wrong type or hash is told apart and counted.
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


def _ours(message: Any) -> bytes:
    return convert.to_ros(message)[1]


@dataclass(frozen=True)
class Outgoing:
    """Our topic `topic` published to ROS 2 as `name` (relative to the namespace)."""

    topic: keys.Topic
    name: str
    ros_type: str
    encode: Callable[[Any], bytes]


@dataclass(frozen=True)
class Incoming:
    """ROS 2 topic `name` (relative to the namespace) taken in as `decode`'s message."""

    name: str
    ros_type: str
    decode: Callable[[bytes], m.Message]


OUTGOING: tuple[Outgoing, ...] = (
    Outgoing(keys.FACE, "face_position", types.POINT_STAMPED, convert.face_to_ros),
    Outgoing(keys.PRESENCE, "radar_presence", PRESENCE, _ours),
    Outgoing(keys.EXPRESSION, "screen_expression", EXPRESSION, _ours),
    Outgoing(keys.DEVICE_FREE, "audio_device_is_free", types.BOOL, convert.bool_to_ros),
)


def _expression(payload: bytes) -> m.Message:
    return convert.from_ros(payload, m.ScreenExpression)


INCOMING: tuple[Incoming, ...] = (
    Incoming("screen_expression", EXPRESSION, _expression),
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
