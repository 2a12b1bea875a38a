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
