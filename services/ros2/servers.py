"""The bridge's ROS 2 service servers and `/play_sound` action server, on the bus.

rmw_zenoh serves a ROS 2 service as a Zenoh queryable on
`<domain>/<name>/<DDS type>/<hash>`: the request's CDR is the query's
payload, its attachment names the client (sequence number, GID), and the
reply carries the same sequence number and GID back. Each server here
declares its queryable under any type and hash and its `SS` graph token
after it (a client that sees the token is heard):

* a query of another type or hash is counted (`wrong_type`) and gets no
  reply, as no rmw_zenoh server would match it;
* a request without a well-formed attachment or whose CDR does not decode
  is counted (`malformed`) and gets an error reply saying why (an rmw_zenoh
  client logs it; a real server would stay silent, the client waits the same);
* otherwise our service is called and its `TriggerReply` is the response,
  a call that fails (no player) answered with success false and the reason.

`ActionServer` serves `/play_sound` over `audio/play_sound`: a goal first
takes an `app` lease on `audio` (as the SDK's `bot.play` does, so the
controller's greeting does not talk over it; no controller, no lease;
refused, goal rejected), then goes to our action; `audio/play_sound/status`
becomes the feedback topic (volatile) and the status topic (transient
local, depth 1, as rcl_action's: a client that starts late gets the last
array) and, when the goal ends, the answer to every waiting `get_result`
(and the lease is given back); cancel_goal goes to `audio/play_sound/cancel`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from functools import partial

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import action, bridge, convert, services, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime import leasing
from buddybot.runtime.diagnostics import RateLimitedLog
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.handles import RawQuery
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node

CALL_TIMEOUT_S = 3.0
MAX_WAITING = 8
"""get_result queries one goal may hold open (a client asks once)."""
COUNTERS = ("service_calls", "service_errors", "goals", "goals_refused", "cancels")

Declare = Callable[[wire.Kind, bridge.Route, wire.Qos], object]
"""Declares one graph token of the bridge's node (kind, route, QoS)."""
Publish = Callable[[bridge.Route, wire.Qos], Callable[[bytes], None]]
"""Declares a ROS 2 publisher (and its token); returns its put."""


class Servers:
    """The services of `services.SERVICES` and the `/play_sound` action."""

    def __init__(self, node: Node, settings: Ros2Settings, declare: Declare,
                 publish: Publish) -> None:
        self.node = node
        self.settings = settings
        self._declare = declare
        self._warn = RateLimitedLog(node.log)
        for name in COUNTERS:
            node.diagnostics.values[name] = 0
        self.action = ActionServer(self, publish)

    # --- shared: one queryable per service, checked the same way ---------------------------

    def serve(self, route: bridge.Route,
              handler: Callable[[RawQuery, wire.Attachment], None]) -> None:
        self.node.serve_raw(route.any_type_key, partial(self._on_query, route, handler),
                            complete=True)  # rmw_zenoh's clients ask complete ones only
        self._declare("SS", route, services.SERVICE_QOS)

    def _on_query(self, route: bridge.Route, handler: Callable[[RawQuery, wire.Attachment], None],
                  query: RawQuery) -> None:
        try:
            type_name, type_hash = bridge.split_key(query.key)
        except wire.WireError:
            type_name, type_hash = "", ""
        if type_name != wire.dds_type_name(route.ros_type) or type_hash != route.type_hash:
            self.node.diagnostics.increment("wrong_type")
            self._warn.warning("wrong_type", "no reply to a request on %s of another type or "
                               "hash: %s", route.ros_name, clip(query.key))
            return
        try:
            info = services.request_info(query.attachment)
            handler(query, info)
        except (convert.ConvertError, wire.WireError) as exc:
            self.refuse(route, query, exc)

    def refuse(self, route: bridge.Route, query: RawQuery, exc: Exception) -> None:
        self.node.diagnostics.increment("malformed")
        self._warn.warning("malformed", "refused a malformed request on %s: %s",
                           route.ros_name, clip(exc))
        query.reply_err(f"{route.ros_name}: {clip(exc)}")

    @staticmethod
    def reply(query: RawQuery, info: wire.Attachment, payload: bytes) -> None:
        query.reply(query.key, payload, encoding="application/cdr",
                    attachment=services.reply_attachment(info, time.time_ns()))

    # --- the audio services -------------------------------------------------------------

    def start(self) -> None:
        for entry in services.SERVICES:
            route = bridge.route(self.settings, entry.name, entry.ros_type)
            self.serve(route, partial(self._on_service, entry))
        self.action.start()

    def _on_service(self, entry: services.RosService, query: RawQuery,
                    info: wire.Attachment) -> None:
        request = services.request_from_ros(query.payload, entry)
        try:
            reply: m.TriggerReply = self.node.call(entry.service, request,
                                                   timeout=CALL_TIMEOUT_S)
        except ServiceError as exc:
            self.node.diagnostics.increment("service_errors")
            self._warn.warning("service_errors", "%s from ROS 2 failed: %s",
                               entry.service.pattern, clip(exc))
            reply = m.TriggerReply(success=False, message=clip(exc))
        self.node.diagnostics.increment("service_calls")
        self.reply(query, info, services.reply_to_ros(reply, entry))

    def close(self) -> None:
        self.action.close()


class ActionServer:
    """`/play_sound` over `audio/play_sound` (see the module's doc)."""

    def __init__(self, servers: Servers, publish: Publish) -> None:
        self.servers = servers
        self.node = servers.node
        self._publish = publish
        self.goals = action.Goals()
        self._lock = threading.Lock()
        self._waiting: dict[bytes, list[tuple[RawQuery, wire.Attachment]]] = {}
        self._feedback: Callable[[bytes], None] = lambda _payload: None
        self._status: Callable[[bytes], None] = lambda _payload: None

    def route(self, part: str, ros_type: str) -> bridge.Route:
        return bridge.route(self.servers.settings, action.part(part), ros_type)

    def start(self) -> None:
        self._feedback = self._publish(self.route("feedback", action.FEEDBACK),
                                       action.FEEDBACK_QOS)
        self._status = self._publish(self.route("status", action.STATUS), action.STATUS_QOS)
        self.node.subscribe(keys.PLAY_SOUND_STATUS, self.on_status, delivery="queue")
        handlers = {"send_goal": self.on_send_goal, "cancel_goal": self.on_cancel,
                    "get_result": self.on_get_result}
        for name, ros_type in action.SERVICES.items():
            self.servers.serve(self.route(name, ros_type), handlers[name])

    # --- goals --------------------------------------------------------------------------

    def on_send_goal(self, query: RawQuery, info: wire.Attachment) -> None:
        uuid, goal = action.decode_send_goal(query.payload)
        accepted = self._start(uuid, goal)
        self.servers.reply(query, info, action.encode_send_goal_reply(accepted, time.time_ns()))
        if accepted:
            self._publish_status()

    def _start(self, uuid: bytes, goal: m.PlaySound) -> bool:
        """Lease, then our action; True when the goal is in the book."""
        with self._lock:
            known = uuid in self.goals
        if known:
            return self._refused(goal, f"goal id {uuid.hex()} already used")
        granted, lease_id = self._lease()
        if not granted:
            return False
        try:
            reply: m.PlaySoundReply = self.node.call(keys.PLAY_SOUND, goal,
                                                     timeout=CALL_TIMEOUT_S)
        except ServiceError as exc:
            self._release(lease_id)
            return self._refused(goal, str(exc))
        if not reply.accepted:
            self._release(lease_id)
            return self._refused(goal, reply.message)
        try:
            with self._lock:
                added = self.goals.add(uuid, reply.goal_id, time.time_ns(), lease_id)
        except ValueError as exc:  # the same id twice at once
            self._cancel_ours(reply.goal_id)
            self._release(lease_id)
            return self._refused(goal, str(exc))
        self.node.diagnostics.increment("goals")
        self.node.log.info("sound %r from ROS 2 (goal %s)", clip(goal.sound), reply.goal_id)
        if added.done:
            self._ended(added)
        return True

    def _lease(self) -> tuple[bool, str | None]:
        """(granted, the `audio` lease's id): no id when no controller answers
        (nobody to share the speaker with); not granted when it refused."""
        try:
            return True, leasing.acquire(
                self.node, leasing.request(self.node, ["audio"], "app"), CALL_TIMEOUT_S)
        except leasing.LeaseRefused as exc:
            self.node.diagnostics.increment("goals_refused")
            self.node.log.warning("sound from ROS 2 refused: %s", clip(exc))
            return False, None
        except ServiceError as exc:
            self.node.log.info("playing without an audio lease: %s", clip(exc))
            return True, None

    def _release(self, lease_id: str | None) -> None:
        if lease_id is None:
            return
        try:
            leasing.release(self.node, lease_id, "sound ended", CALL_TIMEOUT_S)
        except ServiceError as exc:
            self.node.log.info("audio lease %s not released: %s", lease_id, clip(exc))

    def _refused(self, goal: m.PlaySound, reason: str) -> bool:
        self.node.diagnostics.increment("goals_refused")
        self.node.log.warning("sound %r from ROS 2 refused: %s", clip(goal.sound), clip(reason))
        return False

    def _cancel_ours(self, goal_id: str) -> bool:
        try:
            reply: m.TriggerReply = self.node.call(
                keys.PLAY_SOUND_CANCEL, m.CancelGoal(goal_id=goal_id), timeout=CALL_TIMEOUT_S)
        except ServiceError as exc:
            self.node.log.warning("cancel of goal %s failed: %s", goal_id, clip(exc))
            return False
        return reply.success

    # --- our statuses -> feedback, status, results ---------------------------------------

    def on_status(self, status: m.PlaySoundStatus, _key: str) -> None:
        with self._lock:
            goal = self.goals.update(status)
            if goal is None:
                return
            payload = action.encode_feedback(goal)
        self._feedback(payload)
        self._publish_status()
        if goal.done:
            self._ended(goal)

    def _ended(self, goal: action.Goal) -> None:
        """Answer the waiting get_result queries; give the lease back."""
        with self._lock:
            waiting = self._waiting.pop(goal.uuid, [])
            lease_id, goal.lease_id = goal.lease_id, None
        result = action.encode_result(goal.code, goal.state, goal.message)
        for query, info in waiting:
            self.servers.reply(query, info, result)
            query.finish()
        self._release(lease_id)

    def _publish_status(self) -> None:
        with self._lock:
            payload = action.encode_status(self.goals.listed())
        self._status(payload)

    def on_get_result(self, query: RawQuery, info: wire.Attachment) -> None:
        uuid = action.decode_get_result(query.payload)
        with self._lock:
            goal = self.goals.get(uuid)
            waiting = self._waiting.setdefault(uuid, []) if goal and not goal.done else None
            if waiting is not None and len(waiting) < MAX_WAITING:
                waiting.append((query, info))
                query.defer()
                return
        if goal is None:
            payload = action.encode_result(action.UNKNOWN, "", "unknown goal")
        elif waiting is not None:
            query.reply_err(f"{MAX_WAITING} result requests already wait for this goal")
            return
        else:
            payload = action.encode_result(goal.code, goal.state, goal.message)
        self.servers.reply(query, info, payload)

    def on_cancel(self, query: RawQuery, info: wire.Attachment) -> None:
        uuid, stamp_ns = action.decode_cancel(query.payload)
        with self._lock:
            code, targets = self.goals.to_cancel(uuid, stamp_ns)
        canceling = [g for g in targets if self._cancel_ours(g.goal_id)]
        if targets and not canceling:
            code = action.ERROR_REJECTED
        with self._lock:
            for goal in canceling:
                goal.canceling = True
        self.node.diagnostics.increment("cancels")
        self.servers.reply(query, info, action.encode_cancel_reply(code, canceling))
        if canceling:
            self._publish_status()

    def close(self) -> None:
        """Give back the leases of goals still playing (their sounds go on); end
        the waiting get_result queries unanswered (the server is going away)."""
        with self._lock:
            leases = [g.lease_id for g in self.goals.listed() if g.lease_id]
            waiting = [query for queries in self._waiting.values() for query, _ in queries]
            self._waiting.clear()
        for query in waiting:
            query.finish()
        for lease_id in leases:
            self._release(lease_id)
