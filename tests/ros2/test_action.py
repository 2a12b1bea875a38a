"""The `/play_sound` action's ROS 2 side: its CDR checked against
mcap-ros2-support (not ours), built from the checked-in `.action` file, and
the goal book's rules (statuses, cancel requests, bounds)."""

from __future__ import annotations

from typing import Any

import pytest

from buddybot.contract import messages as m
from buddybot.ros2 import action, bridge, convert, interfaces, types, wire

from .test_convert import SEPARATOR, their_decoder, their_encoder

GOAL, RESULT, FEEDBACK = (part.split("\n", 1)[1] if part.startswith("# ") else part
                          for part in ((interfaces.ROOT / "action" / "PlaySound.action")
                                       .read_text().split("\n---\n")))
PKG = "buddybot_interfaces"
UUID = f"{SEPARATOR}\nMSG: unique_identifier_msgs/UUID\nuint8[16] uuid\n"
TIME = f"{SEPARATOR}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
INFO = (f"{SEPARATOR}\nMSG: action_msgs/GoalInfo\nunique_identifier_msgs/UUID goal_id\n"
        f"builtin_interfaces/Time stamp\n{UUID}{TIME}")


def nested(name: str, text: str) -> str:
    return f"{SEPARATOR}\nMSG: {PKG}/{name}\n{text}"


SCHEMAS = {
    "SendGoal_Request": (f"unique_identifier_msgs/UUID goal_id\n{PKG}/PlaySound_Goal goal\n"
                         f"{UUID}{nested('PlaySound_Goal', GOAL)}"),
    "SendGoal_Response": f"bool accepted\nbuiltin_interfaces/Time stamp\n{TIME}",
    "GetResult_Request": f"unique_identifier_msgs/UUID goal_id\n{UUID}",
    "GetResult_Response": (f"int8 status\n{PKG}/PlaySound_Result result\n"
                           f"{nested('PlaySound_Result', RESULT)}"),
    "FeedbackMessage": (f"unique_identifier_msgs/UUID goal_id\n{PKG}/PlaySound_Feedback "
                        f"feedback\n{UUID}{nested('PlaySound_Feedback', FEEDBACK)}"),
    "CancelGoal_Request": f"action_msgs/GoalInfo goal_info\n{INFO}",
    "CancelGoal_Response": f"int8 return_code\naction_msgs/GoalInfo[] goals_canceling\n{INFO}",
    "GoalStatusArray": (f"action_msgs/GoalStatus[] status_list\n{SEPARATOR}\n"
                        f"MSG: action_msgs/GoalStatus\naction_msgs/GoalInfo goal_info\n"
                        f"int8 status\n{INFO}"),
}
ID = bytes(range(16))


def theirs(name: str) -> Any:
    return their_decoder(f"x/{name}", SCHEMAS[name])


def encoded(name: str, value: dict[str, Any]) -> bytes:
    return bytes(their_encoder(f"x/{name}", SCHEMAS[name])(value))


def goal(uuid: bytes = ID, goal_id: str = "g1", stamp_ns: int = 10) -> action.Goal:
    return action.Goal(uuid, goal_id, stamp_ns)


def status(goal_id: str, state: str, progress: float = 0.0, message: str = "") -> Any:
    return m.PlaySoundStatus(goal_id=goal_id, state=state,  # type: ignore[arg-type]
                             progress=progress, message=message)


def test_the_names_and_types_are_rcl_actions() -> None:
    assert action.part("send_goal") == "play_sound/_action/send_goal"
    assert wire.dds_type_name(action.SEND_GOAL) == \
        "buddybot_interfaces::action::dds_::PlaySound_SendGoal_"
    assert wire.dds_type_name(action.FEEDBACK) == \
        "buddybot_interfaces::action::dds_::PlaySound_FeedbackMessage_"
    assert wire.dds_type_name(action.CANCEL_GOAL) == "action_msgs::srv::dds_::CancelGoal_"
    for ros_type in (*action.SERVICES.values(), *action.TOPICS.values()):
        assert types.type_hash(ros_type).startswith("RIHS01_")


def test_the_topics_qos_is_rcl_actions_default() -> None:
    """rcl_action's status profile: reliable, transient local, keep last 1 (its
    `default_qos.h`); feedback: rmw's default (reliable, volatile, depth 10)."""
    assert action.STATUS_QOS.format() == ":1:,1:,:,:,,"
    assert bridge.cache(action.STATUS_QOS) == 1
    assert action.FEEDBACK_QOS.format() == "::,10:,:,:,,"
    assert bridge.cache(action.FEEDBACK_QOS) is None


def test_a_goal_encoded_by_another_implementation() -> None:
    payload = encoded("SendGoal_Request", {"goal_id": {"uuid": list(ID)},
                                           "goal": {"sound": "hello"}})
    assert action.decode_send_goal(payload) == (ID, m.PlaySound(sound="hello"))


def test_the_replies_decode_with_another_implementation() -> None:
    reply = theirs("SendGoal_Response")(action.encode_send_goal_reply(True, 3_000_000_007))
    assert (reply.accepted, reply.stamp.sec, reply.stamp.nanosec) == (True, 3, 7)
    result = theirs("GetResult_Response")(action.encode_result(action.SUCCEEDED, "SUCCEEDED",
                                                               "done"))
    assert (result.status, result.result.state, result.result.message) == (4, "SUCCEEDED",
                                                                           "done")
    g = goal()
    g.state, g.progress = "PLAYING", 0.5
    feedback = theirs("FeedbackMessage")(action.encode_feedback(g))
    assert (bytes(feedback.goal_id.uuid), feedback.feedback.state,
            feedback.feedback.progress) == (ID, "PLAYING", 0.5)
    array = theirs("GoalStatusArray")(action.encode_status([g, goal(bytes(16), "g2", 11)]))
    assert [(bytes(s.goal_info.goal_id.uuid), s.status) for s in array.status_list] == [
        (ID, action.EXECUTING), (bytes(16), action.ACCEPTED)]
    cancel = theirs("CancelGoal_Response")(action.encode_cancel_reply(action.ERROR_NONE, [g]))
    assert cancel.return_code == 0 and bytes(cancel.goals_canceling[0].goal_id.uuid) == ID


def test_requests_by_id_encoded_by_another_implementation() -> None:
    assert action.decode_get_result(encoded("GetResult_Request", {"goal_id": {"uuid": list(ID)}})) \
        == ID
    cancel = encoded("CancelGoal_Request", {"goal_info": {"goal_id": {"uuid": list(ID)},
                                                          "stamp": {"sec": 2, "nanosec": 5}}})
    assert action.decode_cancel(cancel) == (ID, 2_000_000_005)


@pytest.mark.parametrize("payload", [b"", b"junk", wire.CDR_LE + ID,
                                     wire.CDR_LE + ID + b"\x01\x00\x00\x00\x00"])
def test_bad_goals_are_refused(payload: bytes) -> None:
    """No header, short, a goal cut off, an empty sound (min length 1)."""
    with pytest.raises(convert.ConvertError):
        action.decode_send_goal(payload)


def test_statuses_become_the_goals_and_early_ones_are_kept() -> None:
    goals = action.Goals()
    assert goals.update(status("g1", "ACCEPTED")) is None  # before the reply was read
    assert goals.update(status("g1", "PLAYING", 0.2)) is None
    g = goals.add(ID, "g1", 10, "lease-1")
    assert (g.state, g.progress, g.code) == ("PLAYING", 0.2, action.EXECUTING)
    assert goals.update(status("g1", "SUCCEEDED", 1.0)) is g and g.done
    assert g.code == action.SUCCEEDED
    assert goals.update(status("g1", "ABORTED")) is None  # ended stays ended
    with pytest.raises(ValueError, match="already exists"):
        goals.add(ID, "g9", 11, None)


def test_cancel_rules() -> None:
    goals = action.Goals()
    a = goals.add(b"a" * 16, "ga", 10, None)
    b = goals.add(b"b" * 16, "gb", 20, None)
    c = goals.add(b"c" * 16, "gc", 30, None)
    goals.update(status("gc", "SUCCEEDED"))
    zero = action.ZERO_UUID
    assert goals.to_cancel(zero, 0) == (action.ERROR_NONE, [a, b])
    assert goals.to_cancel(zero, 15) == (action.ERROR_NONE, [a])
    assert goals.to_cancel(b.uuid, 0) == (action.ERROR_NONE, [b])
    assert goals.to_cancel(b.uuid, 15) == (action.ERROR_NONE, [b, a])
    assert goals.to_cancel(b"x" * 16, 0) == (action.ERROR_UNKNOWN_GOAL_ID, [])
    assert goals.to_cancel(c.uuid, 0) == (action.ERROR_GOAL_TERMINATED, [])
    a.canceling = True
    assert a.code == action.CANCELING


def test_the_book_is_bounded_and_drops_ended_goals_first() -> None:
    goals = action.Goals()
    first = goals.add(b"\x00" * 15 + b"\x01", "first", 1, None)
    for i in range(action.MAX_GOALS):
        g = goals.add(i.to_bytes(2, "big") * 8, f"g{i}", 10 + i, None)
        if i == 0:
            goals.update(status(g.goal_id, "SUCCEEDED"))
    listed = goals.listed()
    assert len(listed) == action.MAX_GOALS
    assert first in listed and "g0" not in {g.goal_id for g in listed}
