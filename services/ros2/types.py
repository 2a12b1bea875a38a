"""The ROS 2 types the bridge speaks, in one rosbags typestore, with RIHS01 hashes.

rosbags ships Jazzy's standard messages (geometry_msgs/msg/PointStamped and
PoseArray, sensor_msgs/msg/Image and CompressedImage, std_msgs/msg/Bool, ...) but no
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

from buddybot.ros2 import hri_msgs, interfaces

POINT_STAMPED = "geometry_msgs/msg/PointStamped"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
BOOL = "std_msgs/msg/Bool"
FLOAT32 = "std_msgs/msg/Float32"
STRING = "std_msgs/msg/String"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
TRIGGER = "std_srvs/srv/Trigger"
CANCEL_GOAL = "action_msgs/srv/CancelGoal"
GOAL_STATUS_ARRAY = "action_msgs/msg/GoalStatusArray"
STANDARD_MESSAGES = (POINT_STAMPED, IMAGE, COMPRESSED_IMAGE, BOOL, FLOAT32, STRING, TF_MESSAGE,
                     POSE_ARRAY)
"""Standard ROS 2 messages the bridge uses (shipped by rosbags' Jazzy store)."""

OURS = interfaces.PACKAGE

STANDARD_SERVICES: dict[str, tuple[str, str]] = {
    TRIGGER: ("", "bool success\nstring message\n"),
    CANCEL_GOAL: ("action_msgs/msg/GoalInfo goal_info\n",
                  "int8 ERROR_NONE=0\nint8 ERROR_REJECTED=1\nint8 ERROR_UNKNOWN_GOAL_ID=2\n"
                  "int8 ERROR_GOAL_TERMINATED=3\nint8 return_code\n"
                  "action_msgs/msg/GoalInfo[] goals_canceling\n"),
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


def _service_msgs(pkg: str, base: str, request: str, response: str) -> dict[str, Any]:
    """Parse trees of service `base`'s request, response, event and the service
    struct the hash is taken of, all named `pkg/msg/<base>[_<part>]` (renamed by
    the caller: rosbags' parser knows only `msg` names)."""
    msg = f"{pkg}/msg/{base}"
    parts = {
        "_Request": request,
        "_Response": response,
        "_Event": (f"service_msgs/msg/ServiceEventInfo info\n{msg}_Request[<=1] request\n"
                   f"{msg}_Response[<=1] response\n"),
        "": (f"{msg}_Request request_message\n{msg}_Response response_message\n"
             f"{msg}_Event event_message\n"),
    }
    types: dict[str, Any] = {}
    for suffix, text in parts.items():
        types.update(get_types_from_msg(text, f"{msg}{suffix}"))
    return types


def _moved(types: dict[str, Any], pkg: str, kind: str) -> dict[str, Any]:
    """`types` with every `pkg/msg/` name it defines renamed `pkg/<kind>/`."""
    for name in [n for n in types if n.startswith(f"{pkg}/msg/")]:
        types = _renamed(types, name, f"{pkg}/{kind}/{name.rsplit('/', 1)[1]}")
    return types


def _service_types(name: str, request: str, response: str) -> dict[str, Any]:
    """Parse trees of service `name` (`pkg/srv/Name`): request, response, event
    and the service struct the hash is taken of."""
    pkg, kind, base = name.split("/")
    assert kind == "srv", name
    return _moved(_service_msgs(pkg, base, request, response), pkg, "srv")


ACTION_SERVICES = ("SendGoal", "GetResult")
"""The services rosidl derives from an action (its cancel service is the
shared action_msgs/srv/CancelGoal)."""


def action_types(name: str, goal: str, result: str, feedback: str) -> dict[str, Any]:
    """Parse trees of action `name` (`pkg/action/Name`): its goal, result and
    feedback, and what rosidl derives from them: `Name_FeedbackMessage` (the
    feedback topic's type) and the services `Name_SendGoal` and `Name_GetResult`
    (REP-2016 hashes each like any service)."""
    pkg, _, base = name.split("/")
    msg = f"{pkg}/msg/{base}"
    uuid = "unique_identifier_msgs/msg/UUID goal_id\n"
    types: dict[str, Any] = {}
    for suffix, text in (("Goal", goal), ("Result", result), ("Feedback", feedback),
                         ("FeedbackMessage", f"{uuid}{msg}_Feedback feedback\n")):
        types.update(get_types_from_msg(text, f"{msg}_{suffix}"))
    types.update(_service_msgs(pkg, f"{base}_SendGoal", f"{uuid}{msg}_Goal goal\n",
                               "bool accepted\nbuiltin_interfaces/msg/Time stamp\n"))
    types.update(_service_msgs(pkg, f"{base}_GetResult", uuid,
                               f"int8 status\n{msg}_Result result\n"))
    return _moved(types, pkg, "action")


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
    """A new store: Jazzy's standard types, std_srvs/srv/Trigger, the hri_msgs the
    bridge publishes and buddybot_interfaces."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for name, definition in list(store.fielddefs.items()):
        store.fielddefs[name] = _char_as_uint8(definition)
    types: dict[str, Any] = {}
    for name, text in hri_msgs.DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
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
            types.update(action_types(f"{OURS}/action/{base}", goal, result, feedback))
    store.register(types)
    return store


def type_hash(name: str) -> str:
    """RIHS01 hash string (`RIHS01_<64 hex>`) of message or service `name`
    (`pkg/msg/Name`, `pkg/srv/Name`). KeyError for a type the store lacks."""
    store = typestore()
    if name not in store.fielddefs:
        raise KeyError(f"unknown ROS 2 type {name!r}")
    return str(store.hash_rihs01(name))
