"""`buddybot run ros2-bridge`: the robot's topics on a ROS 2 graph (rmw_zenoh wire format).

One node, on the robot's router:

* for each entry of `bridge.OUTGOING` it subscribes to our key and
  republishes every message as CDR on the entry's rmw_zenoh key, with the
  attachment (sequence number, source timestamp, the publisher's GID);
* it declares the graph's liveliness tokens: one for the ROS 2 node, one
  per publisher, one per subscription, so `ros2 node list` and `ros2 topic
  list` see them;
* for each entry of `bridge.INCOMING` it subscribes to the topic under any
  type and hash: a sample of another type or hash is counted
  (`wrong_type`), a payload that does not decode is counted (`malformed`),
  and a `/screen_expression` goes to the controller under the bridge's
  `app` lease on `expression` (a refusal is counted, `refused`). The bridge
  never publishes the robot's keys itself;
* it serves the audio services and the `/play_sound` action as ROS 2
  services (`servers.Servers`, with their `SS` and `MP` tokens).

Off by default: `up` starts it only with `up --ros2` or `[ros2] enabled = true`.
"""

from __future__ import annotations

import argparse
import itertools
import os
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, servers, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.diagnostics import RateLimitedLog
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.handles import RawPublisher
from buddybot.runtime.leasing import LeaseHolder, LeaseRefused
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.service import ServiceContext

CALL_TIMEOUT_S = 3.0
DEFAULT_QOS = wire.Qos(depth=10)
"""rmw_zenoh's default profile with depth 10 (reliable, volatile, keep last)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    settings_option(parser, "--domain-id", struct=Ros2Settings, field="domain_id")
    settings_option(parser, "--namespace", struct=Ros2Settings, field="namespace")


def settings_from(ctx: ServiceContext) -> Ros2Settings:
    """`[ros2]` with the command line on top."""
    return merge(ctx.config.section(Ros2Settings), ctx.args)


class RosPublisher:
    """One ROS 2 publisher: its key, GID and sequence numbers."""

    def __init__(self, publisher: RawPublisher) -> None:
        self.publisher = publisher
        self.gid = os.urandom(wire.GID_SIZE)
        self._sequence = itertools.count(1)
        self._lock = threading.Lock()

    def put(self, payload: bytes) -> None:
        with self._lock:
            attachment = wire.Attachment(next(self._sequence), time.time_ns(), self.gid)
            self.publisher.put(payload, attachment.encode())


class Ros2Bridge:
    """The node side: the tables of `bridge` declared on the bus."""

    def __init__(self, node: Node, settings: Ros2Settings) -> None:
        self.node = node
        self.settings = settings
        self.lease = LeaseHolder(node, ["expression"], "app", CALL_TIMEOUT_S)
        self._warn = RateLimitedLog(node.log)
        """A flood of bad ROS samples is counted in full but logged once per 5 s."""
        self._entities = itertools.count(1)
        self.node_id = 0
        self._publishers: dict[str, RosPublisher] = {}
        self.sent: dict[str, int] = {}
        for name in ("malformed", "wrong_type", "refused", "commands", "encode_errors"):
            node.diagnostics.values[name] = 0
        self.servers = servers.Servers(node, settings, self._token, self._publisher)
        """The ROS 2 services and the `/play_sound` action (servers.py)."""

    def _token(self, kind: wire.Kind, route: bridge.Route | None = None,
               qos: wire.Qos = DEFAULT_QOS) -> None:
        extra: dict[str, Any] = {}
        entity = self.node_id
        if route is not None:
            entity = next(self._entities)
            extra = {"name": route.ros_name, "type_name": wire.dds_type_name(route.ros_type),
                     "type_hash": route.type_hash, "qos": qos}
        token = wire.GraphToken(
            domain_id=self.settings.domain_id, session_id=self.node.instance,
            node_id=self.node_id, entity_id=entity, kind=kind, enclave="",
            namespace=self.settings.namespace, node_name=bridge.NODE_NAME, **extra)
        self.node.declare_token(token.format())

    def start(self) -> None:
        self._token("NN")
        self.node.subscribe(keys.LEASES, self.on_leases, delivery="inline")
        for out in bridge.OUTGOING:
            route = bridge.route(self.settings, out.name, out.ros_type)
            publisher = RosPublisher(self.node.raw_publisher(route.key, "application/cdr"))
            self._publishers[route.ros_name] = publisher
            self.node.subscribe(out.topic, partial(self.on_ours, out, route, publisher),
                                delivery="inline")
            self._token("MP", route)
        for inc in bridge.INCOMING:
            route = bridge.route(self.settings, inc.name, inc.ros_type)
            self.node.subscribe_raw(route.any_type_key, partial(self.on_ros, inc, route),
                                    delivery="queue", remote_only=True)
            self._token("MS", route)  # after the subscriber: a peer seeing it is heard
        self.servers.start()

    def _publisher(self, route: bridge.Route, qos: wire.Qos) -> Callable[[bytes], None]:
        """A ROS 2 publisher of the servers (the action's topics), with its token."""
        publisher = RosPublisher(self.node.raw_publisher(route.key, "application/cdr"))
        self._token("MP", route, qos)
        return publisher.put

    def on_ours(self, out: bridge.Outgoing, route: bridge.Route, publisher: RosPublisher,
                msg: Any, _key: str) -> None:
        try:
            payload = out.encode(msg)
        except (convert.ConvertError, ValueError, TypeError) as exc:
            self.node.diagnostics.increment("encode_errors")
            self.node.log.warning("%s not sent to %s: %s", type(msg).__name__,
                                  route.ros_name, clip(exc))
            return
        publisher.put(payload)
        self.sent[route.ros_name] = self.sent.get(route.ros_name, 0) + 1

    def on_leases(self, state: m.Leases, _key: str) -> None:
        self.lease.forget_unless_in(state)

    def on_ros(self, inc: bridge.Incoming, route: bridge.Route, key: str, payload: bytes,
               _encoding: str) -> None:
        """On the subscription's worker (the lease calls block)."""
        try:
            type_name, type_hash = bridge.split_key(key)
        except wire.WireError:
            type_name, type_hash = "", ""
        if type_name != wire.dds_type_name(route.ros_type) or type_hash != route.type_hash:
            self.node.diagnostics.increment("wrong_type")
            self._warn.warning("wrong_type", "dropped a sample on %s of another type or "
                               "hash: %s", route.ros_name, clip(key))
            return
        try:
            msg = inc.decode(payload)
        except convert.ConvertError as exc:
            self.node.diagnostics.increment("malformed")
            self._warn.warning("malformed", "dropped a malformed sample on %s: %s",
                               route.ros_name, clip(exc))
            return
        assert isinstance(msg, m.ScreenExpression)
        try:
            self.lease.acquire()
            self.lease.command(expression=msg.action)
        except LeaseRefused as exc:
            self.node.diagnostics.increment("refused")
            self._warn.warning("refused", "%s from ROS 2 refused: %s", msg.action.name,
                               clip(exc))
            return
        except ServiceError as exc:
            self.node.diagnostics.increment("refused")
            self._warn.warning("undelivered", "%s from ROS 2 not delivered: %s",
                               msg.action.name, clip(exc))
            return
        self.node.diagnostics.increment("commands")
        self.node.log.info("expression %s from ROS 2", msg.action.name)

    def update_diagnostics(self) -> None:
        for name, count in self.sent.items():
            self.node.diagnostics.values[f"sent {name}"] = count

    def close(self) -> None:
        self.servers.close()
        try:
            self.lease.release("ros2 bridge stopped")
        except ServiceError as exc:
            self.node.log.info("lease not released at stop: %s", clip(exc))


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    node = ctx.node()
    try:
        ros = Ros2Bridge(node, settings)
        ros.start()
        node.log.info("ROS 2 bridge on domain %d, namespace %s", settings.domain_id,
                      settings.namespace)
        node.every(1.0, ros.update_diagnostics, name="ros2-diagnostics")
        node.spin()
        ros.close()
    finally:
        node.close()
    return 0
