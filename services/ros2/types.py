"""The ROS 2 types the bridge speaks, in one rosbags typestore, with RIHS01 hashes.

rosbags ships Jazzy's standard messages (geometry_msgs/msg/PointStamped,
sensor_msgs/msg/Image and CompressedImage, std_msgs/msg/Bool, ...) but no
services; `std_srvs/srv/Trigger` and our `buddybot_interfaces` (generated
from the contract by `interfaces`, the same text as the checked-in files)
are registered here. rmw_zenoh puts a type's RIHS01 hash (REP-2016) in
every key expression and graph token, so a wrong hash means a ROS 2 peer
never matches: `type_hash` gives it for messages and services alike.

A service's hash is the hash of its type description: a struct of the
service's name with the fields `request_message`, `response_message` and
`event_message` (`<Name>_Event`: `service_msgs/msg/ServiceEventInfo info`,
`<Name>_Request[<=1] request`, `<Name>_Response[<=1] response`). rosbags'
message parser knows only `msg` names, so service types are parsed under a
`msg` name and renamed (`_renamed`). rosidl turns a `.msg` file's `char`
into `uint8` before it hashes (`ServiceEventInfo.client_gid` is `char[16]`);
rosbags hashes it as `char`, which gives every service a wrong hash, so the
store's `char` fields are rewritten to `uint8` (`_char_as_uint8`; the CDR
bytes are the same). The hash of example_interfaces/srv/AddTwoInts then
equals the one rmw_zenoh's design doc shows (tests/ros2/test_types.py).
"""

from __future__ import annotations

import functools
from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from buddybot.ros2 import interfaces

POINT_STAMPED = "geometry_msgs/msg/PointStamped"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
BOOL = "std_msgs/msg/Bool"
TRIGGER = "std_srvs/srv/Trigger"
STANDARD_MESSAGES = (POINT_STAMPED, IMAGE, COMPRESSED_IMAGE, BOOL)
"""Standard ROS 2 messages the bridge uses (shipped by rosbags' Jazzy store)."""

OURS = interfaces.PACKAGE

STANDARD_SERVICES: dict[str, tuple[str, str]] = {
    TRIGGER: ("", "bool success\nstring message\n"),
}
"""Standard services the bridge uses: name -> (request, response) `.msg` text."""


def _renamed(types: dict[str, Any], old: str, new: str) -> dict[str, Any]:
    """`types` with the type `old` (and every reference to it) named `new`."""

    def fix(desc: Any) -> Any:
        if isinstance(desc, tuple):
            return tuple(fix(x) for x in desc)
        if isinstance(desc, list):
            return [fix(x) for x in desc]
        return new if desc == old else desc

    return {new if name == old else name: fix(value) for name, value in types.items()}


def _service_types(name: str, request: str, response: str) -> dict[str, Any]:
    """Parse trees of service `name` (`pkg/srv/Name`): request, response, event
    and the service struct the hash is taken of."""
    pkg, kind, base = name.split("/")
    assert kind == "srv", name
    parts = {
        "Request": request,
        "Response": response,
        "Event": (f"service_msgs/msg/ServiceEventInfo info\n{pkg}/msg/{base}_Request[<=1] request\n"
                  f"{pkg}/msg/{base}_Response[<=1] response\n"),
        "": (f"{pkg}/msg/{base}_Request request_message\n"
             f"{pkg}/msg/{base}_Response response_message\n"
             f"{pkg}/msg/{base}_Event event_message\n"),
    }
    types: dict[str, Any] = {}
    for suffix, text in parts.items():
        types.update(get_types_from_msg(text, f"{pkg}/msg/{base}{'_' if suffix else ''}{suffix}"))
    for suffix in parts:
        tail = f"{base}_{suffix}" if suffix else base
        types = _renamed(types, f"{pkg}/msg/{tail}", f"{pkg}/srv/{tail}")
    return types


def _action_types(name: str, goal: str, result: str, feedback: str) -> dict[str, Any]:
    """Parse trees of the goal, result and feedback of action `name` (`pkg/action/Name`)."""
    pkg, _, base = name.split("/")
    types: dict[str, Any] = {}
    for suffix, text in (("Goal", goal), ("Result", result), ("Feedback", feedback)):
        types.update(get_types_from_msg(text, f"{pkg}/msg/{base}_{suffix}"))
    for suffix in ("Goal", "Result", "Feedback"):
        types = _renamed(types, f"{pkg}/msg/{base}_{suffix}", f"{pkg}/action/{base}_{suffix}")
    return types


def _char_as_uint8(desc: Any) -> Any:
    if isinstance(desc, tuple):
        if len(desc) == 2 and desc[0] == "char" and isinstance(desc[1], int):
            return ("uint8", desc[1])
        return tuple(_char_as_uint8(x) for x in desc)
    if isinstance(desc, list):
        return [_char_as_uint8(x) for x in desc]
    return desc


def _sections(text: str) -> list[str]:
    return [part.lstrip("\n") for part in text.split("\n---\n")]


@functools.cache
def typestore() -> Typestore:
    """The bridge's store (built once; read-only after)."""
    return build_typestore()


def build_typestore() -> Typestore:
    """A new store: Jazzy's standard types, std_srvs/srv/Trigger and buddybot_interfaces."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, definition in list(store.fielddefs.items()):
        store.fielddefs[name] = _char_as_uint8(definition)
    types: dict[str, Any] = {}
    for name, (request, response) in STANDARD_SERVICES.items():
        types.update(_service_types(name, request, response))
    for path, text in interfaces.generate().items():
        folder, _, file = path.partition("/")
        base = file.rsplit(".", 1)[0]
        if folder == "msg":
            types.update(get_types_from_msg(text, f"{OURS}/msg/{base}"))
        elif folder == "srv":
            request, response = _sections(text)
            types.update(_service_types(f"{OURS}/srv/{base}", request, response))
        elif folder == "action":
            goal, result, feedback = _sections(text)
            types.update(_action_types(f"{OURS}/action/{base}", goal, result, feedback))
    store.register(types)
    return store


def type_hash(name: str) -> str:
    """RIHS01 hash string (`RIHS01_<64 hex>`) of message or service `name`
    (`pkg/msg/Name`, `pkg/srv/Name`). KeyError for a type the store lacks."""
    store = typestore()
    if name not in store.fielddefs:
        raise KeyError(f"unknown ROS 2 type {name!r}")
    return str(store.hash_rihs01(name))
