"""Config table `[ros2]` (a pure msgspec struct): where the bridge meets ROS 2.

Off by default: the bridge runs under `up` only with `up --ros2` or
`enabled = true` (docs/ros2.md).
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

NAMESPACE = r"^/$|^(/[A-Za-z_][A-Za-z0-9_]*)+$"
"""A ROS namespace: `/`, or `/`-separated name tokens (no trailing `/`)."""


class Ros2Settings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[ros2]`: the ROS 2 bridge (rmw_zenoh wire format)."""

    enabled: Annotated[bool, msgspec.Meta(
        description="start the ROS 2 bridge with `up` (as `up --ros2` does)")] = False
    # ROS_DOMAIN_ID: rmw_zenoh puts it first in every key, so peers on another
    # domain never match.
    domain_id: Annotated[int, msgspec.Meta(
        ge=0, le=232, description="ROS_DOMAIN_ID of the ROS 2 graph (0..232)")] = 0
    namespace: Annotated[str, msgspec.Meta(
        pattern=NAMESPACE, max_length=200, examples=["/robot1", "/lab/buddy"],
        description="namespace of the bridge's node and topics (`/`: the plain "
        "ROS 2 names, /face_position ...)")] = "/"
    robot_frame: Annotated[str, msgspec.Meta(
        pattern=r"^[A-Za-z_][A-Za-z0-9_/]*$", max_length=200,
        examples=["camera_front", "base_link"],
        description="the TF frame the persons' frames (`person_<id>` on /tf) hang "
        "from: the camera's, where the people model measures from")] = "camera_front"
    raw_image: Annotated[Literal["raw", "compressed"], msgspec.Meta(
        description="/raw_image as sensor_msgs/msg/Image (`raw`, bgr8) or as "
        "sensor_msgs/msg/CompressedImage (`compressed`, JPEG)")] = "raw"
    # A ROS 2 node is a peer like any other: a flood of samples on one topic is
    # dropped before decoding, so it never costs the robot more than this.
    max_incoming_hz: Annotated[float, msgspec.Meta(
        gt=0, le=1000, description="samples per second taken in per ROS 2 topic "
        "(more are dropped and counted as `flooded`)")] = 50.0
    incoming_burst: Annotated[int, msgspec.Meta(
        ge=1, le=1000, description="samples taken in at once per ROS 2 topic "
        "before `max_incoming_hz` applies")] = 20
    # A lease taken for a remote peer ends when the peer goes quiet, so one
    # ROS 2 sample never keeps the eyes from the robot's own behaviour.
    lease_idle_s: Annotated[float, msgspec.Meta(
        gt=0, le=3600, extra={"live": True},
        description="seconds without a ROS 2 expression (or gaze) after which the "
        "bridge gives that lease back")] = 5.0
