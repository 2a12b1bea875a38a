"""The bridge's ROS 2 services and `/play_sound` action (services/ros2/servers.py)
through a real router, met by a client that is not ours: a plain Zenoh session
querying as rmw_zenoh's clients do (CDR payload, the attachment, complete
queryables only), with mcap-ros2-support's CDR encoder and decoder; the audio
services run for real on the null device (tests/audio)."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import action, bridge, services, types, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.node import Node, zenoh_config
from buddybot.tools.testing import Collector, Process, retry_until
from tests.audio.conftest import (  # noqa: F401 (fixture)
    Audio,
    audio,
    beep_config,
    send_goal,
)

from .test_action import encoded, theirs
from .test_convert import their_decoder
from .test_service import late_sample

pytestmark = pytest.mark.integration

SETTINGS = Ros2Settings(domain_id=4)
GID = bytes(range(16, 32))
TRIGGER_RESPONSE = "bool success\nstring message\n"
STOP = bridge.route(SETTINGS, "stop_audio_file", types.TRIGGER)
PLAY_FILE = bridge.route(SETTINGS, "play_audio_file", services.PLAY_AUDIO_FILE)
ROUTES = {name: bridge.route(SETTINGS, action.part(name), ros_type)
          for name, ros_type in (*action.SERVICES.items(), *action.TOPICS.items())}


@pytest.fixture
def sounds(audio: Callable[..., Audio]) -> Callable[..., Audio]:  # noqa: F811
    """The audio action and player on the null device (tests/audio/conftest.py)."""
    return audio


@pytest.fixture
def ros(endpoint: str) -> Iterator[zenoh.Session]:
    """A plain Zenoh session on the test router: no BuddyBot node, no tokens."""
    session = zenoh.open(zenoh_config(connect=[endpoint]))
    yield session
    session.close()


def start_bridge(spawn: Callable[..., Process], ros: zenoh.Session) -> list[wire.GraphToken]:
    spawn("ros2-bridge", "--domain-id", str(SETTINGS.domain_id))
    last = ROUTES["get_result"].ros_name  # the last token the bridge declares

    def complete() -> list[wire.GraphToken] | None:
        tokens = [wire.GraphToken.parse(str(reply.ok.key_expr)) for reply in
                  ros.liveliness().get(f"{wire.PREFIX}/{SETTINGS.domain_id}/**", timeout=2.0)
                  if reply.ok is not None]
        return tokens if any(t.name == last for t in tokens) else None

    return retry_until(complete, 30, 0.2, "the bridge's graph tokens")


def call(ros: zenoh.Session, route: bridge.Route | str, payload: bytes, sequence: int,
         attachment: bool = True, timeout: float = 10.0) -> list[zenoh.Reply]:
    """One request as rmw_zenoh's client sends it; every reply."""
    extra: dict[str, Any] = {}
    if attachment:
        extra["attachment"] = wire.Attachment(sequence, m.now_ns(), GID).encode()
    key = route if isinstance(route, str) else route.key
    return list(ros.get(key, payload=payload, target=zenoh.QueryTarget.ALL_COMPLETE,
                        timeout=timeout, **extra))


def ok(replies: list[zenoh.Reply], sequence: int) -> bytes:
    """The one good reply's payload; its attachment pairs it with the request."""
    assert len(replies) == 1 and replies[0].ok is not None, replies
    sample = replies[0].ok
    assert sample.attachment is not None
    back = wire.Attachment.decode(sample.attachment.to_bytes())
    assert (back.sequence, back.gid) == (sequence, GID) and back.timestamp_ns > 0
    return sample.payload.to_bytes()


def counter(diag: Collector[m.DiagnosticStatus], name: str) -> int:
    messages = diag.messages
    return int(messages[-1].values.get(name, 0)) if messages else 0


def test_stop_audio_file_stops_a_playing_sound_and_bad_requests_are_counted(
        sounds: Callable[..., Audio], spawn: Callable[..., Process], ros: zenoh.Session,
        probe: Node, tmp_path: Any) -> None:
    config, _ = beep_config(tmp_path, 20.0)
    a = sounds(config)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="ros2-bridge")
    tokens = start_bridge(spawn, ros)
    assert {t.name for t in tokens if t.kind == "SS"} == {
        "/play_audio_file", "/stop_audio_file", "/pause_audio_file", "/resume_audio_file",
        "/play_sound/_action/send_goal", "/play_sound/_action/cancel_goal",
        "/play_sound/_action/get_result"}
    qos = {t.name: t.qos for t in tokens if t.kind == "MP"}
    assert qos["/play_sound/_action/status"] == action.STATUS_QOS  # transient local, depth 1
    assert qos["/play_sound/_action/status"].format() == ":1:,1:,:,:,,"
    assert qos["/play_sound/_action/feedback"].format() == "::,10:,:,:,,"  # volatile
    stop_token = next(t for t in tokens if t.name == "/stop_audio_file")
    assert (stop_token.type_name, stop_token.type_hash) == (
        "std_srvs::srv::dds_::Trigger_", STOP.type_hash)

    goal = send_goal(probe, "beep")
    a.status.wait_for(lambda s: s.goal_id == goal.goal_id and s.state == "PLAYING", 30,
                      "the beep playing")
    asked = m.now_ns()
    reply = their_decoder("x/Trigger_Response", TRIGGER_RESPONSE)(
        ok(call(ros, STOP, wire.CDR_LE + b"\x00", 7), 7))
    assert reply.success, reply.message
    a.free.wait_for(lambda b: b.data and b.stamp_ns > asked, 30, "the player stopped")

    bad = call(ros, PLAY_FILE, wire.CDR_LE + b"junk", 8)
    assert len(bad) == 1 and bad[0].err is not None
    assert "/play_audio_file" in bad[0].err.payload.to_string()
    unattached = call(ros, STOP, wire.CDR_LE + b"\x00", 9, attachment=False)
    assert len(unattached) == 1 and unattached[0].err is not None
    wrong = STOP.key.rsplit("/", 1)[0] + "/RIHS01_" + "0" * 64
    assert call(ros, wrong, wire.CDR_LE + b"\x00", 10, timeout=3.0) == []
    retry_until(lambda: counter(diag, "wrong_type") >= 1 and counter(diag, "malformed") >= 2,
                30, 0.2, "the bad requests counted")
    assert counter(diag, "service_calls") == 1 and a.alive()


def goal_request(uuid: bytes, sound: str) -> bytes:
    return encoded("SendGoal_Request", {"goal_id": {"uuid": list(uuid)},
                                        "goal": {"sound": sound}})


def by_id(uuid: bytes) -> bytes:
    return encoded("GetResult_Request", {"goal_id": {"uuid": list(uuid)}})


def test_a_play_sound_goal_plays_under_an_audio_lease_and_its_result_comes_at_the_end(
        sounds: Callable[..., Audio], spawn: Callable[..., Process], ros: zenoh.Session,
        probe: Node, tmp_path: Any) -> None:
    config, samples = beep_config(tmp_path, 0.6)
    a = sounds(config)
    spawn("eyes")
    retry_until(lambda: any(keys.LEASE_ACQUIRE.pattern in " ".join(i.services)
                            for i in probe.node_infos(1.0)), 30, 0.2, "the arbiter's leases")
    leases = Collector[m.Leases](probe, keys.LEASES)
    start_bridge(spawn, ros)
    seen: dict[str, list[bytes]] = {"feedback": [], "status": []}
    for name in seen:
        ros.declare_subscriber(ROUTES[name].key,
                               lambda s, n=name: seen[n].append(s.payload.to_bytes()))
    uuid = os.urandom(16)

    accepted = theirs("SendGoal_Response")(
        ok(call(ros, ROUTES["send_goal"], goal_request(uuid, "beep"), 1), 1))
    assert accepted.accepted and accepted.stamp.sec > 0
    held = leases.wait_for(lambda s: any(x.holder == "ros2-bridge" and x.resources == ["audio"]
                                         for x in s.leases), 30, "the bridge's audio lease")
    result = theirs("GetResult_Response")(
        ok(call(ros, ROUTES["get_result"], by_id(uuid), 2, timeout=30), 2))
    assert (result.status, result.result.state) == (action.SUCCEEDED, "SUCCEEDED")

    lease_id = next(x.lease_id for x in held.leases if x.holder == "ros2-bridge")
    leases.wait_for(lambda s: any(e.lease_id == lease_id and e.reason == "released"
                                  for e in s.ended), 30, "the lease given back")

    def codes() -> list[int]:
        arrays = [theirs("GoalStatusArray")(p) for p in list(seen["status"])]
        return [s.status for arr in arrays for s in arr.status_list
                if bytes(s.goal_info.goal_id.uuid) == uuid]

    retry_until(lambda: action.SUCCEEDED in codes(), 10, 0.1, "SUCCEEDED on the status topic")
    assert action.EXECUTING in codes()
    feedback = [theirs("FeedbackMessage")(p) for p in list(seen["feedback"])]
    assert any(f.feedback.state == "PLAYING" and bytes(f.goal_id.uuid) == uuid for f in feedback)

    unknown = theirs("GetResult_Response")(ok(call(ros, ROUTES["get_result"],
                                                   by_id(bytes(16)), 3), 3))
    assert unknown.status == action.UNKNOWN
    a.player.stop()  # the tap file is complete once the player exited
    assert (a.tap_samples() == samples).all()


def test_a_play_sound_goal_canceled_from_ros_2_and_its_status_kept_for_late_clients(
        sounds: Callable[..., Audio], spawn: Callable[..., Process], ros: zenoh.Session,
        probe: Node, tmp_path: Any) -> None:
    config, _ = beep_config(tmp_path, 20.0)
    a = sounds(config)
    start_bridge(spawn, ros)
    uuid = os.urandom(16)
    assert theirs("SendGoal_Response")(
        ok(call(ros, ROUTES["send_goal"], goal_request(uuid, "beep"), 1), 1)).accepted
    a.status.wait_for(lambda s: s.state == "PLAYING", 30, "the beep playing")
    cancel = theirs("CancelGoal_Response")(ok(call(ros, ROUTES["cancel_goal"], encoded(
        "CancelGoal_Request", {"goal_info": {"goal_id": {"uuid": list(uuid)},
                                             "stamp": {"sec": 0, "nanosec": 0}}}), 2), 2))
    assert cancel.return_code == action.ERROR_NONE
    assert [bytes(g.goal_id.uuid) for g in cancel.goals_canceling] == [uuid]
    result = theirs("GetResult_Response")(
        ok(call(ros, ROUTES["get_result"], by_id(uuid), 3, timeout=30), 3))
    assert (result.status, result.result.state) == (action.CANCELED, "CANCELED")
    latest = theirs("GoalStatusArray")(late_sample(ros, ROUTES["status"].key))  # after the end
    assert [(bytes(s.goal_info.goal_id.uuid), s.status) for s in latest.status_list] == [
        (uuid, action.CANCELED)]
    assert theirs("SendGoal_Response")(ok(call(ros, ROUTES["send_goal"], goal_request(
        uuid, "beep"), 4), 4)).accepted is False  # a goal id is used once
