"""The `/play_sound` action as ROS 2 sees it (pure): names, types, CDR, goal book.

A ROS 2 action is three services and two topics under `<name>/_action/`
(rcl_action's naming, which rmw_zenoh keys as any other service or topic):
`send_goal` (`PlaySound_SendGoal`: goal id + goal -> accepted + stamp),
`cancel_goal` (action_msgs/srv/CancelGoal), `get_result`
(`PlaySound_GetResult`: goal id -> status + result, answered when the goal
ends), `feedback` (`PlaySound_FeedbackMessage`) and `status`
(action_msgs/msg/GoalStatusArray). Our `audio/play_sound` action is the
same idea with our own goal ids: `Goals` pairs a ROS goal id (a 16-byte
UUID the client picks) with ours, follows `audio/play_sound/status`, and
says what the status array lists, what a cancel request names and what a
result holds. Not thread-safe: its one user holds a lock.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, types
from buddybot.runtime.limits import BoundedDict

NAME = "play_sound"
ACTION = f"{types.OURS}/action/PlaySound"
SEND_GOAL = f"{ACTION}_SendGoal"
GET_RESULT = f"{ACTION}_GetResult"
FEEDBACK = f"{ACTION}_FeedbackMessage"
CANCEL_GOAL = types.CANCEL_GOAL
STATUS = types.GOAL_STATUS_ARRAY

SERVICES = {"send_goal": SEND_GOAL, "cancel_goal": CANCEL_GOAL, "get_result": GET_RESULT}
"""`_action/<part>` -> service type."""
TOPICS = {"feedback": FEEDBACK, "status": STATUS}
"""`_action/<part>` -> message type."""

STATUS_QOS = bridge.LATCHED_QOS
"""The status topic: rcl_action's default status profile (reliable, transient
local, keep last 1), so a client that starts late gets the last array at once."""
FEEDBACK_QOS = bridge.DEFAULT_QOS
"""The feedback topic: rcl_action's default (rmw's default profile: reliable,
volatile, depth 10); a late client has no use for past progress."""

# action_msgs/msg/GoalStatus
UNKNOWN, ACCEPTED, EXECUTING, CANCELING, SUCCEEDED, CANCELED, ABORTED = range(7)
CODES: dict[str, int] = {"ACCEPTED": ACCEPTED, "PLAYING": EXECUTING, "SUCCEEDED": SUCCEEDED,
                         "CANCELED": CANCELED, "ABORTED": ABORTED}
"""Our goal states -> action_msgs/msg/GoalStatus codes."""
# action_msgs/srv/CancelGoal_Response
ERROR_NONE, ERROR_REJECTED, ERROR_UNKNOWN_GOAL_ID, ERROR_GOAL_TERMINATED = range(4)

MAX_GOALS = 32
"""Goals the status array lists (the oldest ended ones leave first)."""
MAX_EARLY = 64
"""Statuses kept for goal ids whose `audio/play_sound` reply is not read yet."""
ZERO_UUID = bytes(16)


def part(name: str) -> str:
    """`play_sound/_action/<name>` (relative to the namespace)."""
    return f"{NAME}/_action/{name}"


# --- CDR ---------------------------------------------------------------------------


def _new(ros_type: str, **fields: Any) -> Any:
    return types.typestore().types[ros_type](**fields)


def _uuid(uuid: bytes) -> Any:
    return _new("unique_identifier_msgs/msg/UUID", uuid=np.frombuffer(uuid, dtype=np.uint8))


def _time(stamp_ns: int) -> Any:
    return _new("builtin_interfaces/msg/Time", sec=stamp_ns // 1_000_000_000,
                nanosec=stamp_ns % 1_000_000_000)


def _stamp_ns(time: Any) -> int:
    return max(0, int(time.sec) * 1_000_000_000 + int(time.nanosec))


def decode_send_goal(payload: bytes | memoryview) -> tuple[bytes, m.PlaySound]:
    """(ROS goal id, our goal) of a send_goal request; ConvertError."""
    ros_type = f"{SEND_GOAL}_Request"
    msg = convert.deserialize(payload, ros_type)
    goal = convert._checked(m.PlaySound, {"sound": msg.goal.sound}, ros_type)
    return msg.goal_id.uuid.tobytes(), goal


def encode_send_goal_reply(accepted: bool, stamp_ns: int) -> bytes:
    ros_type = f"{SEND_GOAL}_Response"
    return convert.serialize(_new(ros_type, accepted=accepted, stamp=_time(stamp_ns)), ros_type)


def decode_get_result(payload: bytes | memoryview) -> bytes:
    """The ROS goal id a get_result request asks about; ConvertError."""
    return bytes(convert.deserialize(payload, f"{GET_RESULT}_Request").goal_id.uuid.tobytes())


def encode_result(code: int, state: str, message: str) -> bytes:
    ros_type = f"{GET_RESULT}_Response"
    result = _new(f"{ACTION}_Result", state=state, message=message[:4096])
    return convert.serialize(_new(ros_type, status=code, result=result), ros_type)


def decode_cancel(payload: bytes | memoryview) -> tuple[bytes, int]:
    """(ROS goal id, stamp ns) of a cancel_goal request; ConvertError."""
    msg = convert.deserialize(payload, f"{CANCEL_GOAL}_Request")
    return msg.goal_info.goal_id.uuid.tobytes(), _stamp_ns(msg.goal_info.stamp)


def encode_cancel_reply(code: int, goals: list[Goal]) -> bytes:
    ros_type = f"{CANCEL_GOAL}_Response"
    infos = [_new("action_msgs/msg/GoalInfo", goal_id=_uuid(g.uuid), stamp=_time(g.stamp_ns))
             for g in goals]
    return convert.serialize(_new(ros_type, return_code=code, goals_canceling=infos), ros_type)


def encode_feedback(goal: Goal) -> bytes:
    feedback = _new(f"{ACTION}_Feedback", state=goal.state, progress=goal.progress)
    return convert.serialize(_new(FEEDBACK, goal_id=_uuid(goal.uuid), feedback=feedback),
                             FEEDBACK)


def encode_status(goals: list[Goal]) -> bytes:
    statuses = [_new("action_msgs/msg/GoalStatus",
                     goal_info=_new("action_msgs/msg/GoalInfo", goal_id=_uuid(g.uuid),
                                    stamp=_time(g.stamp_ns)),
                     status=g.code) for g in goals]
    return convert.serialize(_new(STATUS, status_list=statuses), STATUS)


# --- the goal book ---------------------------------------------------------------------


@dataclass
class Goal:
    """One ROS 2 goal, as our action reports it."""

    uuid: bytes
    goal_id: str
    """Ours (`PlaySoundReply.goal_id`)."""
    stamp_ns: int
    """When it was accepted (the status array's GoalInfo stamp)."""
    lease_id: str | None = None
    """The `audio` lease taken for it, released when it ends."""
    state: m.GoalState = "ACCEPTED"
    progress: float = 0.0
    message: str = ""
    canceling: bool = False

    @property
    def done(self) -> bool:
        return self.state in m.TERMINAL_GOAL_STATES

    @property
    def code(self) -> int:
        if self.canceling and not self.done:
            return CANCELING
        return CODES[self.state]


class Goals:
    """ROS 2 goals <-> ours, bounded (`MAX_GOALS`, `MAX_EARLY`)."""

    def __init__(self) -> None:
        self._by_uuid: dict[bytes, Goal] = {}
        self._by_id: dict[str, Goal] = {}
        self._early: BoundedDict[str, m.PlaySoundStatus] = BoundedDict(MAX_EARLY)
        """Statuses that came before their goal's reply was read (our action
        publishes ACCEPTED, even the end of a short sound, before it replies)."""

    def __contains__(self, uuid: bytes) -> bool:
        return uuid in self._by_uuid

    def get(self, uuid: bytes) -> Goal | None:
        return self._by_uuid.get(uuid)

    def add(self, uuid: bytes, goal_id: str, stamp_ns: int, lease_id: str | None) -> Goal:
        """A goal our action accepted; the statuses it already published applied.
        ValueError for a ROS goal id already in the book."""
        if uuid in self._by_uuid:
            raise ValueError(f"goal {uuid.hex()} already exists")
        goal = Goal(uuid, goal_id, stamp_ns, lease_id)
        self._by_uuid[uuid] = goal
        self._by_id[goal_id] = goal
        early = self._early.pop(goal_id, None)
        if early is not None:
            self._apply(goal, early)
        self._trim()
        return goal

    def update(self, status: m.PlaySoundStatus) -> Goal | None:
        """Apply a status of ours: the goal it changed, None when it is not one of
        the book's (kept a while: its reply may not be read yet) or had ended."""
        goal = self._by_id.get(status.goal_id)
        if goal is None:
            self._early[status.goal_id] = status
            return None
        if goal.done:
            return None
        self._apply(goal, status)
        return goal

    @staticmethod
    def _apply(goal: Goal, status: m.PlaySoundStatus) -> None:
        goal.state, goal.progress, goal.message = status.state, status.progress, status.message

    def to_cancel(self, uuid: bytes, stamp_ns: int) -> tuple[int, list[Goal]]:
        """(return code, goals to cancel) of a CancelGoal request, by its rules: a
        zero id and zero stamp name every goal; a zero id and a stamp every goal
        accepted at or before it; an id that goal (and, with a stamp, those
        before it too). Only goals not ended are canceled."""
        named: list[Goal] = []
        if uuid != ZERO_UUID:
            goal = self._by_uuid.get(uuid)
            if goal is None and not stamp_ns:
                return ERROR_UNKNOWN_GOAL_ID, []
            if goal is not None:
                named.append(goal)
        if uuid == ZERO_UUID and not stamp_ns:
            named = list(self._by_uuid.values())
        elif stamp_ns:
            named += [g for g in self._by_uuid.values()
                      if g.stamp_ns <= stamp_ns and g not in named]
        active = [g for g in named if not g.done]
        if named and not active and uuid != ZERO_UUID:
            return ERROR_GOAL_TERMINATED, []
        return ERROR_NONE, active

    def listed(self) -> list[Goal]:
        """The goals of the status array, oldest first."""
        return sorted(self._by_uuid.values(), key=lambda g: g.stamp_ns)

    def _trim(self) -> None:
        while len(self._by_uuid) > MAX_GOALS:
            ended = [g for g in self.listed() if g.done]
            oldest = ended[0] if ended else self.listed()[0]
            del self._by_uuid[oldest.uuid]
            self._by_id.pop(oldest.goal_id, None)
