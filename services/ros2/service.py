"""`buddybot run ros2-bridge`: the robot's topics on a ROS 2 graph (rmw_zenoh wire format).

One node, on the robot's router:

* for each entry of `bridge.outgoing(settings)` it subscribes to our key
  and republishes every message as CDR on the entry's rmw_zenoh key, with
  the attachment (sequence number, source timestamp, the publisher's GID);
  a latched entry's publisher keeps its last value for late joiners
  (transient local), an on-demand entry (images) subscribes to our key only
  while a ROS 2 subscription to the topic is in the graph (`OnDemand`);
* it declares the graph's liveliness tokens (node, publishers,
  subscriptions), so `ros2 node list` and `ros2 topic list` see them;
* for each entry of `bridge.INCOMING` it subscribes to the topic under any
  type and hash, counts and drops floods (`flooded`), other types or
  hashes (`wrong_type`) and undecodable payloads (`malformed`), and takes
  `/screen_expression` or `/eye_control` to the controller under the
  bridge's `app` lease (`refused` counted). It never publishes the robot's
  keys itself, and its subscriptions to them only copy, so it never slows them;
* it serves the audio services and the `/play_sound` action as ROS 2
  services (`servers.Servers`, with their `SS` and `MP` tokens).

Off by default: `up` starts it only with `up --ros2` or `[ros2] enabled = true`.
Details: docs/ros2.md, 'The bridge service'.
"""

from __future__ import annotations

import argparse
import ctypes
import itertools
import os
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, hri, servers, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.diagnostics import RateLimitedLog
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.handles import RawPublisher, Subscription, Token, Worker
from buddybot.runtime.leasing import LeaseHolder, LeaseRefused
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.rates import TokenBucket
from buddybot.runtime.service import ServiceContext

CALL_TIMEOUT_S = 3.0
KEPT_BLOCK = 16 << 20
"""Blocks up to this size come from the heap rather than their own mapping."""
KEPT_FREE = 64 << 20
"""Free memory the heap keeps before it gives any back to the system."""
QUEUE_SIZE = 64
IDLE_CHECK_S = 0.25
"""How often leases are checked for a quiet ROS 2 side (`lease_idle_s`)."""
"""Samples of one ROS 2 topic waiting for the controller (oldest dropped)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    settings_option(parser, "--domain-id", struct=Ros2Settings, field="domain_id")
    settings_option(parser, "--namespace", struct=Ros2Settings, field="namespace")
    settings_option(parser, "--raw-image", struct=Ros2Settings, field="raw_image")


def settings_from(ctx: ServiceContext) -> Ros2Settings:
    """`[ros2]` with the command line on top."""
    return merge(ctx.config.section(Ros2Settings), ctx.args)


_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
"""glibc's `mallopt` parameter numbers (malloc.h)."""


def keep_freed_frames() -> bool:
    """Let glibc's heap keep freed camera-sized blocks instead of handing them
    back to the system: every frame passes through about five ~1 MB buffers
    (Zenoh's reassembly, the bytes of the sample, the message's pixels, the
    CDR payload), and by default each is a fresh mapping whose pages the
    kernel zeroes and faults in one by one; at 30 fps that was half the
    bridge's CPU with a `/raw_image` reader (docs/ros2.md, Figures). False
    where the C library is not glibc (nothing changes there)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, KEPT_BLOCK)) and bool(
        mallopt(_M_TRIM_THRESHOLD, KEPT_FREE))


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


class OnDemand:
    """Our key subscribed only while a ROS 2 subscription to its topic is in the
    graph (their `MS` tokens): images cost the bridge nothing while nobody on
    the ROS side reads them, and the detector draws its debug image only while
    this subscription exists. Tokens arrive in Zenoh's thread; the subscription
    is declared or closed on the worker."""

    def __init__(self, name: str, subscribe: Callable[[], Subscription],
                 on_error: Callable[[BaseException], None]) -> None:
        self.readers: set[str] = set()
        self._subscribe = subscribe
        self._subscription: Subscription | None = None
        self._lock = threading.Lock()
        self._worker = Worker(f"ros2-{name}", self._reconcile, latest=True, maxlen=1,
                              on_error=on_error)

    def on_token(self, key: str, alive: bool) -> None:
        with self._lock:
            if alive:
                self.readers.add(key)
            else:
                self.readers.discard(key)
        self._worker.submit()

    def _reconcile(self) -> None:
        with self._lock:
            wanted = bool(self.readers)
        if wanted and self._subscription is None:
            self._subscription = self._subscribe()
        elif not wanted and self._subscription is not None:
            self._subscription.close()
            self._subscription = None

    @property
    def active(self) -> bool:
        return self._subscription is not None

    def close(self) -> None:
        self._worker.close(drop_pending=True)


class Inbox:
    """One ROS 2 subscription's intake: a flood limit checked in Zenoh's thread
    (a sample over it is dropped before anything else is done with it), then
    a worker (the lease calls block) fed in order or with the newest only."""

    def __init__(self, inc: bridge.Incoming, settings: Ros2Settings,
                 handler: Callable[..., None], on_error: Callable[[BaseException], None]
                 ) -> None:
        self.bucket = TokenBucket(settings.max_incoming_hz, settings.incoming_burst,
                                  time.monotonic())
        self._lock = threading.Lock()
        self.worker = Worker(f"ros2-in-{inc.name}", handler, latest=inc.latest,
                             maxlen=QUEUE_SIZE, on_error=on_error)

    def admit(self) -> bool:
        with self._lock:
            return self.bucket.take(time.monotonic())


class Ros2Bridge:
    """The node side: the tables of `bridge` declared on the bus."""

    def __init__(self, node: Node, settings: Ros2Settings) -> None:
        self.node = node
        self.settings = settings
        self.leases = {resource: LeaseHolder(node, [resource], "app", CALL_TIMEOUT_S)
                       for resource in {inc.resource for inc in bridge.INCOMING}}
        """One `app` lease per resource, taken at the first sample that needs it:
        a ROS 2 expression does not take the gaze from face tracking."""
        self._warn = RateLimitedLog(node.log)
        """A flood of bad ROS samples is counted in full but logged once per 5 s."""
        self._entities = itertools.count(1)
        self.node_id = 0
        self._publishers: dict[str, RosPublisher] = {}
        self.on_demand: dict[str, OnDemand] = {}
        self._inboxes: list[Inbox] = []
        self.sent: dict[str, int] = {}
        for name in ("malformed", "wrong_type", "flooded", "refused", "commands",
                     "encode_errors"):
            node.diagnostics.values[name] = 0
        self.servers = servers.Servers(node, settings, self._token, self._publisher)
        """The ROS 2 services and the `/play_sound` action (servers.py)."""
        self._planner = hri.HriPlanner(settings.robot_frame)
        self._people_lock = threading.Lock()
        self._people_busy = False
        """The worker is opening or closing a person's topics."""
        self._people_next: m.PeopleState | None = None
        """The newest state that came meanwhile, planned once the worker is done."""
        self._people_worker = Worker("ros2-people-topics", self._people_topics, latest=True,
                                     maxlen=1, on_error=self._on_error)
        self._hri: dict[str, tuple[RosPublisher, Token]] = {}
        """The ROS4HRI publishers by topic name (relative): static ones and each
        present person's."""
        self._last_sample: dict[str, float] = {}
        """Per resource: when its last ROS 2 command came (monotonic)."""
        node.diagnostics.values["idle_released"] = 0

    def _token(self, kind: wire.Kind, route: bridge.Route | None = None,
               qos: wire.Qos = bridge.DEFAULT_QOS) -> Token:
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
        return self.node.declare_token(token.format())

    def _on_error(self, exc: BaseException) -> None:
        self.node.diagnostics.increment("callback_errors")
        self._warn.warning("worker", "ROS 2 bridge worker failed: %r", exc)

    def start(self) -> None:
        self._token("NN")
        self.node.subscribe(keys.LEASES, self.on_leases, delivery="inline")
        for out in bridge.outgoing(self.settings):
            route = bridge.route(self.settings, out.name, out.ros_type)
            publisher = RosPublisher(self.node.raw_publisher(route.key, "application/cdr",
                                                             cache=bridge.cache(out.qos)))
            self._publishers[route.ros_name] = publisher
            subscribe = partial(self.node.subscribe, out.topic,
                                partial(self.on_ours, out, route, publisher),
                                delivery="latest" if out.on_demand else "inline")
            if out.on_demand:
                demand = OnDemand(out.name, subscribe, self._on_error)
                self.on_demand[route.ros_name] = demand
                self.node.watch_tokens(wire.entities_key(
                    self.settings.domain_id, "MS", route.ros_name,
                    wire.dds_type_name(route.ros_type), route.type_hash), demand.on_token)
            else:
                subscribe()
            self._token("MP", route, out.qos)
        for inc in bridge.INCOMING:
            route = bridge.route(self.settings, inc.name, inc.ros_type)
            inbox = Inbox(inc, self.settings, partial(self.on_ros, inc, route), self._on_error)
            self._inboxes.append(inbox)
            self.node.subscribe_raw(route.any_type_key, partial(self.on_sample, route, inbox),
                                    delivery="inline", remote_only=True)
            self._token("MS", route)  # after the subscriber: a peer seeing it is heard
        for name, ros_type in hri.STATIC_TOPICS.items():
            self._hri_topic(name, ros_type)
        people = OnDemand("people", self._subscribe_people, self._on_error)
        for name in hri.DEMAND_TOPICS:  # every ROS4HRI client reads the tracked list
            route = bridge.route(self.settings, name, hri.STATIC_TOPICS[name])
            self.on_demand[route.ros_name] = people
            self.node.watch_tokens(wire.entities_key(
                self.settings.domain_id, "MS", route.ros_name,
                wire.dds_type_name(route.ros_type), route.type_hash), people.on_token)
        self.servers.start()

    def _subscribe_people(self) -> Subscription:
        return self.node.subscribe(keys.PEOPLE_STATE, self.on_people)

    def _hri_topic(self, name: str, ros_type: str) -> None:
        """Declare one ROS4HRI publisher (and its graph token) under `name`."""
        route = bridge.route(self.settings, name, ros_type)
        qos = hri.qos(name)
        publisher = RosPublisher(self.node.raw_publisher(route.key, "application/cdr",
                                                         cache=bridge.cache(qos)))
        self._hri[name] = (publisher, self._token("MP", route, qos))

    def on_people(self, state: m.PeopleState, _key: str) -> None:
        """In Zenoh's callback thread: the people model as ROS4HRI (`hri.HriPlanner`
        decides what is sent; most states send nothing). Samples go out at once,
        as every robot topic's do: handing each state to a thread costs more than
        planning it (docs/ros2.md, Figures). A plan that opens or closes a person's
        topics goes to the worker (declarations never run in Zenoh's thread), and
        while it works only the newest state waits for it."""
        with self._people_lock:
            if self._people_busy:
                self._people_next = state
                return
            plan = self._planner.step(state)
            if not plan.opened and not plan.closed:
                self._apply(plan)
                return
            self._people_busy = True
        self._people_worker.submit(plan)

    def _people_topics(self, plan: hri.Plan) -> None:
        """On the worker: `plan`, then the state that came meanwhile, if any."""
        try:
            while True:
                self._apply(plan)
                with self._people_lock:
                    state, self._people_next = self._people_next, None
                    if state is None:
                        self._people_busy = False
                        return
                    plan = self._planner.step(state)
                    if not plan.opened and not plan.closed:
                        self._apply(plan)
                        self._people_busy = False
                        return
        except BaseException:
            with self._people_lock:
                self._people_busy = False
            raise

    def _apply(self, plan: hri.Plan) -> None:
        """A person's topics open when they arrive and close when they leave."""
        for pid in plan.opened:
            for name, ros_type in hri.PERSON_TOPICS.items():
                self._hri_topic(hri.person_topic(pid, name), ros_type)
        for sample in plan.samples:
            self._hri[sample.name][0].put(sample.payload)
            self.sent[sample.name] = self.sent.get(sample.name, 0) + 1
        for pid in plan.closed:
            for name in hri.PERSON_TOPICS:
                topic = hri.person_topic(pid, name)
                publisher, token = self._hri.pop(topic)
                token.close()
                publisher.publisher.close()
                self.sent.pop(topic, None)

    def _publisher(self, route: bridge.Route, qos: wire.Qos) -> Callable[[bytes], None]:
        """A ROS 2 publisher of the servers (the action's topics), with its token;
        a transient-local one keeps its last samples for late joiners."""
        publisher = RosPublisher(self.node.raw_publisher(route.key, "application/cdr",
                                                         cache=bridge.cache(qos)))
        self._token("MP", route, qos)
        return publisher.put

    def on_ours(self, out: bridge.Outgoing, route: bridge.Route, publisher: RosPublisher,
                msg: Any, _key: str) -> None:
        try:
            payload = out.encode(msg)
        except (convert.ConvertError, ValueError, TypeError) as exc:
            self.node.diagnostics.increment("encode_errors")
            self._warn.warning(f"encode:{route.ros_name}", "%s not sent to %s: %s",
                               type(msg).__name__, route.ros_name, clip(exc))
            return
        publisher.put(payload)
        self.sent[route.ros_name] = self.sent.get(route.ros_name, 0) + 1

    def on_leases(self, state: m.Leases, _key: str) -> None:
        for lease in self.leases.values():
            lease.forget_unless_in(state)

    def on_sample(self, route: bridge.Route, inbox: Inbox, key: str, payload: bytes,
                  _encoding: str) -> None:
        """In Zenoh's thread: the flood limit and the type check, nothing that waits."""
        if not inbox.admit():
            self.node.diagnostics.increment("flooded")
            self._warn.warning(f"flood:{route.ros_name}", "%s: more than %.0f samples/s "
                               "from ROS 2, the excess dropped", route.ros_name,
                               self.settings.max_incoming_hz)
            return
        try:
            type_name, type_hash = bridge.split_key(key)
        except wire.WireError:
            type_name, type_hash = "", ""
        if type_name != wire.dds_type_name(route.ros_type) or type_hash != route.type_hash:
            self.node.diagnostics.increment("wrong_type")
            self._warn.warning("wrong_type", "dropped a sample on %s of another type or "
                               "hash: %s", route.ros_name, clip(key))
            return
        inbox.worker.submit(payload)

    def on_ros(self, inc: bridge.Incoming, route: bridge.Route, payload: bytes) -> None:
        """On the topic's worker (the lease calls block)."""
        try:
            msg = inc.decode(payload)
        except convert.ConvertError as exc:
            self.node.diagnostics.increment("malformed")
            self._warn.warning("malformed", "dropped a malformed sample on %s: %s",
                               route.ros_name, clip(exc))
            return
        lease = self.leases[inc.resource]
        what = msg.action.name if isinstance(msg, m.ScreenExpression) else route.ros_name
        self._last_sample[inc.resource] = time.monotonic()  # before: no idle release meanwhile
        try:
            lease.acquire()
            if isinstance(msg, m.ScreenExpression):
                lease.command(expression=msg.action)
            else:
                assert isinstance(msg, m.EyeControl)
                lease.command(yaw=msg.yaw, pitch=msg.pitch,
                              target_distance_cm=msg.target_distance_cm)
        except LeaseRefused as exc:
            self.node.diagnostics.increment("refused")
            self._warn.warning(f"refused:{inc.resource}", "%s from ROS 2 refused: %s", what,
                               clip(exc))
            return
        except ServiceError as exc:
            self.node.diagnostics.increment("refused")
            self._warn.warning(f"undelivered:{inc.resource}", "%s from ROS 2 not delivered: "
                               "%s", what, clip(exc))
            return
        self.node.diagnostics.increment("commands")
        if isinstance(msg, m.ScreenExpression):
            self.node.log.info("expression %s from ROS 2", what)

    def apply_settings(self, settings: Ros2Settings) -> None:
        """A live change (`buddybot param set ros2-bridge lease_idle_s 2`)."""
        self.settings = settings

    def release_idle(self, now: float | None = None) -> None:
        """Give back each lease whose ROS 2 side sent nothing for `lease_idle_s`:
        the robot's own behaviour takes that part back (a later sample takes a
        new lease)."""
        now = time.monotonic() if now is None else now
        for resource, lease in self.leases.items():
            last = self._last_sample.get(resource)
            if last is not None and lease.release_if_idle(now - last,
                                                          self.settings.lease_idle_s,
                                                          "ROS 2 command"):
                self.node.diagnostics.increment("idle_released")

    def update_diagnostics(self) -> None:
        for name, count in self.sent.items():
            self.node.diagnostics.values[f"sent {name}"] = count
        for name, demand in self.on_demand.items():
            self.node.diagnostics.values[f"readers {name}"] = len(demand.readers)

    def close(self) -> None:
        self.servers.close()
        for demand in set(self.on_demand.values()):
            demand.close()
        for inbox in self._inboxes:
            inbox.worker.close(drop_pending=True)
        self._people_worker.close(drop_pending=True)
        for lease in self.leases.values():
            try:
                lease.release("ros2 bridge stopped")
            except ServiceError as exc:
                self.node.log.info("lease not released at stop: %s", clip(exc))


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    kept = keep_freed_frames()
    node = ctx.node()
    if not kept:
        node.log.info("not glibc: freed frames go back to the system (more CPU per image)")
    try:
        ros = Ros2Bridge(node, settings)
        ros.start()
        node.log.info("ROS 2 bridge on domain %d, namespace %s", settings.domain_id,
                      settings.namespace)
        node.every(1.0, ros.update_diagnostics, name="ros2-diagnostics")
        node.every(IDLE_CHECK_S, ros.release_idle, name="ros2-idle-leases")
        LiveSettings(settings, ros.apply_settings).serve(node)
        node.spin()
        ros.close()
    finally:
        node.close()
    return 0
