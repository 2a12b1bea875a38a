"""RIHS01 hashes equal the values ROS 2 publishes.

The expected values are the ones rmw_zenoh's design doc shows in its key
expression examples (ros2/rmw_zenoh, docs/design.md, section "Topic and
Service name mapping to Zenoh key expressions"): the `chatter` topic's
std_msgs/msg/String and the `add_two_ints` service's
example_interfaces/srv/AddTwoInts.
"""

from __future__ import annotations

import re

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

from buddybot.ros2 import interfaces, types

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


def test_std_msgs_string_hash_equals_rmw_zenohs_design_doc() -> None:
    assert types.type_hash("std_msgs/msg/String") == STRING_HASH


def test_a_service_hash_equals_rmw_zenohs_design_doc() -> None:
    """The service hash needs the service struct and its event message, and
    `char` hashed as rosidl does (uint8): without `_char_as_uint8` it differs."""
    store = types.build_typestore()
    store.register(types._service_types("example_interfaces/srv/AddTwoInts",
                                        "int64 a\nint64 b\n", "int64 sum\n"))
    assert store.hash_rihs01("example_interfaces/srv/AddTwoInts") == ADD_TWO_INTS_HASH


def test_pose_array_hash_is_the_one_public_type_tables_carry() -> None:
    """/ld2450_targets' type: the value public ROS 2 projects list for
    geometry_msgs/msg/PoseArray (corroboration, not an authority)."""
    assert types.type_hash(types.POSE_ARRAY) == (
        "RIHS01_af0cc36d190e104d546d168d6b39df04fa4b4ccecf59cb4c9ed328d3d5004aa0")


def test_char_is_hashed_as_uint8() -> None:
    fields = dict(types.typestore().fielddefs["service_msgs/msg/ServiceEventInfo"][1])
    assert fields["client_gid"] == (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16))


@pytest.mark.parametrize("name", [*types.STANDARD_MESSAGES, types.TRIGGER,
                                  *(f"{types.OURS}/msg/{c.__name__}" for c in interfaces.MESSAGES),
                                  f"{types.OURS}/srv/PlayAudioFile"])
def test_every_type_the_bridge_uses_has_a_hash(name: str) -> None:
    assert re.fullmatch(r"RIHS01_[0-9a-f]{64}", types.type_hash(name))


def test_the_service_parts_are_registered() -> None:
    store = types.typestore()
    for part in ("Request", "Response", "Event"):
        assert f"std_srvs/srv/Trigger_{part}" in store.fielddefs
    for part in ("Goal", "Result", "Feedback"):
        assert f"{types.OURS}/action/PlaySound_{part}" in store.fielddefs
    names = [field for field, _ in store.fielddefs["std_srvs/srv/Trigger"][1]]
    assert names == ["request_message", "response_message", "event_message"]


def test_an_unknown_type_is_refused() -> None:
    with pytest.raises(KeyError, match="nope"):
        types.type_hash("nope/msg/Nope")


def test_our_hashes_change_with_our_definitions() -> None:
    """A changed field changes the hash, so a ROS 2 peer with stale definitions never matches."""
    name = f"{types.OURS}/msg/PupilControl"
    other = get_typestore(Stores.ROS2_JAZZY)
    other.register(get_types_from_msg("uint64 stamp_ns\nfloat32 dilation_percentage\n", name))
    assert other.hash_rihs01(name) != types.type_hash(name)


ROTATE_ABSOLUTE = {
    # `ros2 action info /turtle1/rotate_absolute --verbose` on a real ROS 2
    # installation, as ros2/ros2_documentation prints it (Tutorials,
    # Beginner-CLI-Tools, Understanding-ROS2-Actions).
    "turtlesim_msgs/action/RotateAbsolute_SendGoal":
        "RIHS01_3d5d3cfcbb721f88038eaedcd4af95565360a82b36f1983e3a6c7448d2d18fbe",
    "turtlesim_msgs/action/RotateAbsolute_GetResult":
        "RIHS01_f96fd02477be2a47122fca142e960d407b24850c6eac72047872ba764473c4ef",
    "turtlesim_msgs/action/RotateAbsolute_FeedbackMessage":
        "RIHS01_bef10993e1ee82b35f99f7e390bac1e6cc64e2a3090536887832e122aa71f1b5",
    types.CANCEL_GOAL: "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
    types.GOAL_STATUS_ARRAY:
        "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
}


@pytest.mark.parametrize("name", sorted(ROTATE_ABSOLUTE))
def test_an_actions_derived_types_hash_as_a_real_ros_2_prints_them(name: str) -> None:
    """turtlesim's RotateAbsolute (goal `float32 theta`, result `float32 delta`,
    feedback `float32 remaining`): its SendGoal and GetResult services, its
    FeedbackMessage, and the shared CancelGoal and GoalStatusArray."""
    store = types.build_typestore()
    store.register(types.action_types("turtlesim_msgs/action/RotateAbsolute", "float32 theta\n",
                                      "float32 delta\n", "float32 remaining\n"))
    assert store.hash_rihs01(name) == ROTATE_ABSOLUTE[name]


@pytest.mark.parametrize("suffix", ["SendGoal", "GetResult", "FeedbackMessage"])
def test_our_actions_derived_types_have_hashes(suffix: str) -> None:
    assert re.fullmatch(r"RIHS01_[0-9a-f]{64}",
                        types.type_hash(f"{types.OURS}/action/PlaySound_{suffix}"))
