"""The people model as ROS4HRI (REP-155) topics, planned from `people/state` (pure).

One ROS4HRI person per visit of the people service, id `p<person id>`:

* `/humans/persons/tracked` and `/humans/persons/known` (hri_msgs/IdsList):
  the persons present; known adds the identities of the named ones;
* per person, under `/humans/persons/<id>/`: `engagement_status`
  (hri_msgs/EngagementLevel, our engagement on REP-155's levels),
  `location_confidence` (std_msgs/Float32: 1 while a sensor shows where they
  are, 0.5 while held, 0 without a direction), `anonymous` (std_msgs/Bool)
  and, once the identity service named them (with their consent), `alias`
  (std_msgs/String: the id of that identity, `known_<name>`);
* `/tf` (tf2_msgs/TFMessage): the frame `person_<id>` in the camera's frame
  for each person whose direction is known.

`HriPlanner.step` turns one `people/state` into the samples to send and the
persons whose topics open or close; a value is re-sent only when it
changed (the latched topics keep it for late joiners), the frames at most
every 0.1 s. The state changes with every camera frame, mostly only where
someone is: such a state costs a comparison and, when due, the frames. The
mapping, and what a ROS user adds: docs/ros2.md, 'People as ROS4HRI'.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, hri_msgs, types, wire

TRACKED = "humans/persons/tracked"
KNOWN = "humans/persons/known"
TF = "tf"
PERSON_TOPICS: dict[str, str] = {
    "engagement_status": hri_msgs.ENGAGEMENT_LEVEL,
    "location_confidence": types.FLOAT32,
    "anonymous": types.BOOL,
    "alias": types.STRING,
}
"""A person's topics (under `humans/persons/<id>/`) and their types."""
STATIC_TOPICS: dict[str, str] = {TRACKED: hri_msgs.IDS_LIST, KNOWN: hri_msgs.IDS_LIST,
                                  TF: types.TF_MESSAGE}
"""The topics there while the bridge runs, whoever is present."""
DEMAND_TOPICS = (TRACKED, TF)
"""The people are read (and these topics fed) only while a ROS 2 node subscribes to
one of these: a ROS4HRI client always reads the tracked list, a TF listener /tf."""
TF_PERIOD_NS = 100_000_000
"""Frames at most every 0.1 s (and at once for a new person): `people/state` changes
with every camera frame, and a TF listener interpolates between stamps."""
TF_PERIOD_NS_MAX = 2**62
LEVELS: dict[str, int] = {"NONE": 1, "ENGAGING": 2, "ENGAGED": 3, "DISENGAGING": 4}
"""Our engagement -> REP-155's level (DISENGAGED=1 ... DISENGAGING=4; else UNKNOWN=0)."""


def qos(name: str) -> wire.Qos:
    """The QoS a topic is offered with: the lists and a person's state are latched
    (a late joiner learns who is there), the confidence and the frames stream."""
    if name == TF or name.endswith("/location_confidence"):
        return bridge.DEFAULT_QOS
    return bridge.LATCHED_QOS


def person_id(person: m.Person) -> str:
    return f"p{person.id}"


def person_topic(pid: str, name: str) -> str:
    return f"humans/persons/{pid}/{name}"


def identity_id(name: str) -> str:
    """The ROS4HRI id of an enrolled identity: `known_` and the name in lowercase
    letters, digits and `_` (a ROS name token)."""
    token = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
    return f"known_{token or 'person'}"


def confidence(person: m.Person) -> float:
    if person.yaw_rad is None and person.bearing_rad is None:
        return 0.0
    return 0.5 if person.seen_by == "NONE" else 1.0


def position(person: m.Person) -> tuple[float, float, float] | None:
    """Where a person is in the camera's frame (x ahead, y left, z up), metres;
    None without a direction (a presence radar gives a distance only)."""
    yaw = person.yaw_rad if person.yaw_rad is not None else person.bearing_rad
    if yaw is None:
        return None
    pitch = person.pitch_rad or 0.0
    d = person.distance_m
    return (d * math.cos(pitch) * math.cos(yaw), d * math.cos(pitch) * math.sin(yaw),
            d * math.sin(pitch))


@dataclass(frozen=True)
class Sample:
    """One CDR sample for the ROS 2 topic `name` (relative to the namespace)."""

    name: str
    ros_type: str
    payload: bytes


@dataclass(frozen=True)
class Plan:
    """What one `people/state` asks of the bridge, in order: open the opened
    persons' topics, send the samples, close the closed persons' topics."""

    opened: tuple[str, ...]
    samples: tuple[Sample, ...]
    closed: tuple[str, ...]


@dataclass
class HriPlanner:
    """The values last sent, per topic, so that only changes are sent again."""

    robot_frame: str = "camera_front"
    sent: dict[str, Any] = field(default_factory=dict)
    present: tuple[str, ...] = ()
    frames_at: int = -TF_PERIOD_NS_MAX
    """The stamp of the frames last sent (ns)."""
    shown: tuple[tuple[Any, ...], ...] | None = None
    """What the last state planned in full showed, but for where the people are:
    a state showing the same sends its frames when they are due, else nothing."""

    def step(self, state: m.PeopleState) -> Plan:
        stamp = state.stamp_ns
        shown = tuple((p.id, p.engagement, p.name, confidence(p)) for p in state.people)
        due = stamp - self.frames_at >= TF_PERIOD_NS or stamp < self.frames_at
        if shown == self.shown:  # most states: only a distance or an angle moved
            return Plan((), self._frames(state), ()) if due else NOTHING
        ids = tuple(person_id(p) for p in state.people)
        opened = tuple(i for i in ids if i not in self.present)
        closed = tuple(i for i in self.present if i not in ids)
        for pid in closed:
            for name in PERSON_TOPICS:
                self.sent.pop(person_topic(pid, name), None)
        self.present = ids
        samples: list[Sample] = []
        known = ids + tuple(sorted({identity_id(p.name) for p in state.people if p.name}))
        send = partial(self._changed, samples)
        send(TRACKED, hri_msgs.IDS_LIST, ids, partial(ids_list, stamp))
        send(KNOWN, hri_msgs.IDS_LIST, known, partial(ids_list, stamp))
        for p in state.people:
            pid = person_id(p)
            send(person_topic(pid, "engagement_status"), hri_msgs.ENGAGEMENT_LEVEL,
                 LEVELS.get(p.engagement, 0), partial(engagement_level, stamp))
            send(person_topic(pid, "location_confidence"), types.FLOAT32, confidence(p),
                 float32)
            send(person_topic(pid, "anonymous"), types.BOOL, p.name is None, boolean)
            if p.name is not None:
                send(person_topic(pid, "alias"), types.STRING, identity_id(p.name), string)
        frames = self._frames(state) if due or opened else ()
        self.shown = shown
        return Plan(opened, (*samples, *frames), closed)

    def _frames(self, state: m.PeopleState) -> tuple[Sample, ...]:
        """The frames of those whose direction is known (where they are is worked
        out only when it is sent), if any."""
        frames = [(f"person_{person_id(p)}", where) for p in state.people
                  if (where := position(p)) is not None]
        if not frames:
            return ()
        self.frames_at = state.stamp_ns
        return (Sample(TF, types.TF_MESSAGE,
                       tf_message(state.stamp_ns, self.robot_frame, frames)),)

    def _changed(self, out: list[Sample], name: str, ros_type: str, value: Any,
                 encode: Callable[[Any], bytes]) -> None:
        """Append `value` encoded for topic `name` unless it is the one sent last."""
        if self.sent.get(name, _UNSET) == value:
            return
        self.sent[name] = value
        out.append(Sample(name, ros_type, encode(value)))


_UNSET = object()
NOTHING = Plan((), (), ())


# --- encoding (rosbags' CDR of the standard and hri_msgs types) ---------------------


def _new(ros_type: str, **fields: Any) -> Any:
    return types.typestore().types[ros_type](**fields)


def ids_list(stamp_ns: int, ids: tuple[str, ...]) -> bytes:
    return convert.serialize(_new(hri_msgs.IDS_LIST, header=convert.header(stamp_ns, ""),
                                  ids=list(ids)), hri_msgs.IDS_LIST)


def engagement_level(stamp_ns: int, level: int) -> bytes:
    return convert.serialize(_new(hri_msgs.ENGAGEMENT_LEVEL,
                                  header=convert.header(stamp_ns, ""), level=level),
                             hri_msgs.ENGAGEMENT_LEVEL)


def float32(value: float) -> bytes:
    return convert.serialize(_new(types.FLOAT32, data=value), types.FLOAT32)


def boolean(value: bool) -> bytes:
    return convert.serialize(_new(types.BOOL, data=value), types.BOOL)


def string(value: str) -> bytes:
    return convert.serialize(_new(types.STRING, data=value), types.STRING)


def tf_message(stamp_ns: int, parent: str,
               frames: list[tuple[str, tuple[float, float, float]]]) -> bytes:
    """One transform per (child frame, position) from `parent`, no rotation."""
    store = types.typestore().types
    transforms = [
        store["geometry_msgs/msg/TransformStamped"](
            header=convert.header(stamp_ns, parent), child_frame_id=child,
            transform=store["geometry_msgs/msg/Transform"](
                translation=store["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                rotation=store["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)))
        for child, (x, y, z) in frames]
    return convert.serialize(_new(types.TF_MESSAGE, transforms=transforms), types.TF_MESSAGE)
