"""The robot's audio services as ROS 2 services (pure): names, types, CDR both ways.

The original ROS 2 design's player offers `/play_audio_file` (its own
request: a path) and `/stop_audio_file`, `/pause_audio_file`,
`/resume_audio_file` (std_srvs/srv/Trigger); ours are `audio/play_file`, `audio/stop`,
`audio/pause` and `audio/resume`, and every one answers a `TriggerReply`
(success, message), which is both ROS responses field for field. `SERVICES`
is the table; `request_from_ros` and `reply_to_ros` cross the bridge, the
request checked like any incoming payload (`convert.deserialize`, then the
contract's own checks), and `request_info` reads what rmw_zenoh attaches to
a request (sequence number, the client's GID) so the reply can carry it back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import convert, types, wire

PLAY_AUDIO_FILE = f"{types.OURS}/srv/PlayAudioFile"

SERVICE_QOS = wire.Qos(depth=10)
"""rmw's default services profile (reliable, volatile, keep last 10), as its
graph tokens spell it."""


@dataclass(frozen=True)
class RosService:
    """ROS 2 service `name` (relative to the namespace) served by our `service`."""

    name: str
    ros_type: str
    service: keys.Service


SERVICES: tuple[RosService, ...] = (
    RosService("play_audio_file", PLAY_AUDIO_FILE, keys.PLAY_FILE),
    RosService("stop_audio_file", types.TRIGGER, keys.AUDIO_STOP),
    RosService("pause_audio_file", types.TRIGGER, keys.AUDIO_PAUSE),
    RosService("resume_audio_file", types.TRIGGER, keys.AUDIO_RESUME),
)


def request_from_ros(payload: bytes | memoryview, entry: RosService) -> m.Message:
    """Our request for `entry` from a ROS 2 request payload, checked; ConvertError."""
    ros_type = f"{entry.ros_type}_Request"
    msg = convert.deserialize(payload, ros_type)
    fields: dict[str, Any] = {}
    if entry.service.request is m.PlayAudioFile:
        fields = {"path": msg.path}
    return convert._checked(entry.service.request, fields, ros_type)


def reply_to_ros(reply: m.TriggerReply, entry: RosService) -> bytes:
    """The ROS 2 response of `entry` (success, message) for our reply."""
    ros_type = f"{entry.ros_type}_Response"
    cls = types.typestore().types[ros_type]
    return convert.serialize(cls(success=reply.success, message=reply.message), ros_type)


def request_info(attachment: bytes | None) -> wire.Attachment:
    """The attachment of a ROS 2 request (WireError when absent or malformed:
    rmw_zenoh refuses such a request too)."""
    if attachment is None:
        raise wire.WireError("a request without the rmw_zenoh attachment")
    info = wire.Attachment.decode(attachment)
    if info.sequence < 0 or info.timestamp_ns < 0:
        raise wire.WireError(f"negative sequence number or timestamp in {info}")
    return info


def reply_attachment(request: wire.Attachment, now_ns: int) -> bytes:
    """What rmw_zenoh attaches to a reply: the request's sequence number and
    client GID (how the client pairs them), this reply's timestamp."""
    return wire.Attachment(request.sequence, now_ns, request.gid).encode()
