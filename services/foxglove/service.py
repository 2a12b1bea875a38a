"""`buddybot run foxglove` (and `buddybot foxglove`): every key live in the Foxglove app.

A Foxglove WebSocket server (the `foxglove-sdk` package) fed by one node:

* every catalogue topic but the images is subscribed to all the time;
  each concrete key becomes a channel named by its full key the first
  time it is seen, with its JSON Schema, its messages sent as JSON (encoded
  only while a client subscribes to the channel);
* `camera/<cam>/faces` also feeds `.../faces/annotations`
  (`foxglove.ImageAnnotations`), so the Image panel draws the boxes;
* images are found from the nodes' own reports (`node_info/*`), advertised
  as `foxglove.CompressedImage`, and subscribed to only while a client
  watches them, at most `max_image_fps`;
* three Foxglove services: `eyes/expression` (under the bridge's operator
  lease on `expression`; the controller publishes, never the bridge),
  `eyes/release` and `audio/play_sound`.

Clients reach the SDK's server (on loopback, at a free port) through the
gate (`gate.py`: names, origins, header timeout, connection caps, and
beyond loopback the token, `token.py`). The server starts before the node,
so a busy port fails at once (exit 1). Bad payloads are counted and
dropped (`malformed`), never shown. Details: docs/foxglove.md.
"""

from __future__ import annotations

import logging
import threading
import time
from functools import partial
from typing import Any
from urllib.parse import urlencode

import foxglove
import msgspec

from buddybot.contract import channels, describe, keys
from buddybot.contract import messages as m
from buddybot.foxglove import logic
from buddybot.foxglove.gate import Gate
from buddybot.foxglove.options import add_arguments, settings_from
from buddybot.foxglove.server import FoxgloveServer, service_schema
from buddybot.foxglove.settings import FoxgloveSettings
from buddybot.foxglove.token import token_check
from buddybot.runtime.endpoints import is_wildcard, local_host
from buddybot.runtime.errors import ConfigError, ServiceError
from buddybot.runtime.handles import Subscription
from buddybot.runtime.leasing import LeaseHolder, LeaseRefused
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext
from buddybot.web import auth as web_auth
from buddybot.web.guard import guard_for

__all__ = ["add_arguments", "run", "settings_from"]

DISCOVERY_S = 3.0
"""How often the nodes are asked which image keys they publish."""
QUERY_TIMEOUT_S = 1.0
CALL_TIMEOUT_S = 5.0
APP_URL = "https://app.foxglove.dev"


def urls(host: str, port: int) -> tuple[str, str]:
    """(the WebSocket URL, the Foxglove app link that opens it) for a local viewer."""
    ws = f"ws://{local_host(host)}:{port}"
    return ws, f"{APP_URL}/?{urlencode({'ds': 'foxglove-websocket', 'ds.url': ws})}"


class Bridge:
    """The node side: subscriptions, image demand, services."""

    def __init__(self, node: Node, fox: FoxgloveServer, settings: FoxgloveSettings,
                 gate: Gate | None = None) -> None:
        self.node = node
        self.fox = fox
        self.gate = gate
        self.settings = settings
        self.messages = 0
        self.images_sent = 0
        self.image_errors = 0
        self._images: dict[str, keys.Topic] = {}  # absolute image key -> its topic
        self._image_subs: dict[str, Subscription] = {}
        self._limiters: dict[str, logic.RateLimiter] = {}
        self.lease = LeaseHolder(node, ["expression"], "operator", CALL_TIMEOUT_S)
        self._last_call = 0.0
        """When a client last set the expression (monotonic): the lease's idle clock."""

    def apply_settings(self, settings: FoxgloveSettings) -> None:
        """A live change (`buddybot param set foxglove max_image_fps 5`): the image
        limiters take the new rate at their next frame; the rest needs a restart."""
        self.settings = settings
        for limiter in list(self._limiters.values()):
            limiter.set_rate(settings.max_image_fps)

    # -- everything but images: always on, in Zenoh's thread (nothing here blocks) --

    def subscribe_all(self) -> None:
        for topic in logic.streamed_topics():
            self.node.subscribe(topic, partial(self.on_message, topic), delivery="inline")

    def on_message(self, topic: keys.Topic, msg: Any, relative_key: str) -> None:
        if topic is keys.LEASES:
            self.lease.forget_unless_in(msg)  # broken or ended elsewhere: not used again
        key = f"{self.node.prefix}/{relative_key}"
        channel = self.fox.channel(key, topic)
        if channel is None:
            return
        self.messages += 1
        stamp = getattr(msg, "stamp_ns", 0) or time.time_ns()
        if channel.has_sinks():  # nobody watching: not even encoded
            channel.log(msgspec.json.encode(msg), log_time=stamp)
        if topic is keys.FACES:
            boxes = self.fox.annotations(key)
            if boxes is not None and boxes.has_sinks():
                boxes.log(msgspec.json.encode(channels.annotations(msg)), log_time=stamp)

    # -- images: advertised from node reports, subscribed while watched --

    def discover(self) -> None:
        """Advertise every image key a node says it publishes."""
        if not self.settings.images:
            return
        infos = self.node.node_infos(QUERY_TIMEOUT_S)
        for relative_key in sorted(logic.declared_images(infos)):
            key = f"{self.node.prefix}/{relative_key}"
            topic = logic.topic_of(relative_key)
            if key in self._images or topic is None:
                continue
            if self.fox.channel(key, topic) is not None:
                self._images[key] = topic
                self.node.log.info("image channel %s", clip(key))

    def reconcile(self) -> None:
        """Subscribe to the watched image keys, stop the others."""
        wanted = self.fox.watched() & set(self._images)
        start, stop = logic.plan(wanted, set(self._image_subs))
        for key in stop:
            self._image_subs.pop(key).close()
            self.node.log.info("nobody watches %s: unsubscribed", clip(key))
        for key in start:
            topic = self._images[key]
            params: dict[str, Any] = topic.match(self.node.relative(key)) or {}
            self._limiters[key] = logic.RateLimiter(self.settings.max_image_fps)
            self._image_subs[key] = self.node.subscribe(
                topic, partial(self.on_image, topic), delivery="latest", **params)
            self.node.log.info("a client watches %s: subscribed", clip(key))

    def on_image(self, topic: keys.Topic, msg: m.Image, relative_key: str) -> None:
        """On the subscription's worker (it only ever sees the newest frame)."""
        key = f"{self.node.prefix}/{relative_key}"
        limiter = self._limiters.get(key)
        channel = self.fox.channel(key, topic)
        if limiter is None or channel is None or not limiter.allow(time.monotonic()):
            return
        try:
            data = msgspec.json.encode(channels.compressed_image(msg))
        except channels.ChannelError as exc:
            self.image_errors += 1
            self.node.log.warning("image on %s not shown: %s", clip(key), clip(exc))
            return
        channel.log(data, log_time=msg.stamp_ns)
        self.images_sent += 1

    def manage(self) -> None:
        """The manager thread: discovery every DISCOVERY_S, and image subscriptions
        follow the clients' at once (the SDK's listener sets `changed`)."""
        next_discovery = 0.0
        while not self.node.stop_event.is_set():
            now = time.monotonic()
            try:
                if now >= next_discovery:
                    next_discovery = now + DISCOVERY_S
                    self.discover()
                self.reconcile()
            except Exception as exc:  # a transient bus error: try again next round
                self.node.diagnostics.increment("manager_errors")
                self.node.log.warning("foxglove manager: %s", clip(repr(exc)))
            self.fox.changed.wait(max(0.0, next_discovery - time.monotonic()))
            self.fox.changed.clear()

    def update_diagnostics(self) -> None:
        values = self.node.diagnostics.values
        values["channels"] = self.fox.channel_count()
        values["channels_refused"] = self.fox.refused
        values["watched_channels"] = len(self.fox.watched())
        values["messages"] = self.messages
        values["image_subscriptions"] = len(self._image_subs)
        values["images_sent"] = self.images_sent
        values["images_skipped"] = sum(r.skipped for r in self._limiters.values())
        values["image_errors"] = self.image_errors
        if self.gate is not None:
            values.update(self.gate.counters())
            if not self.gate.alive():
                self.node.diagnostics.set("ERROR", f"not serving: {self.gate.why_dead()}")

    # -- Foxglove services (the SDK runs each call on its own thread: blocking is fine) --

    def services(self) -> list[foxglove.Service]:
        expression = foxglove.Service(
            logic.EXPRESSION_SERVICE, handler=self.set_expression,
            schema=service_schema("buddybot.SetExpression",
                                  logic.request_schema(m.ScreenExpression),
                                  channels.message_schema(m.ScreenExpression)))
        release = foxglove.Service(
            logic.RELEASE_SERVICE, handler=self.release_expression,
            schema=service_schema("buddybot.ReleaseExpression",
                                  logic.request_schema(m.Trigger),
                                  channels.message_schema(m.TriggerReply)))
        play = foxglove.Service(
            logic.PLAY_SOUND_SERVICE, handler=self.play_sound,
            schema=service_schema("buddybot.PlaySound", logic.request_schema(m.PlaySound),
                                  channels.message_schema(m.PlaySoundReply)))
        return [expression, release, play]

    def set_expression(self, request: foxglove.ServiceRequest) -> bytes:
        """Set the expression (`{"action": "EYE_HAPPY"}`; a name or a number)
        through the controller, under the bridge's operator lease on `expression`
        (taken at the first call); a refusal names who holds the expression."""
        msg = describe.parse_message(m.ScreenExpression, _text(request.payload))
        assert isinstance(msg, m.ScreenExpression)
        self._last_call = time.monotonic()  # before: no idle release meanwhile
        try:
            self.lease.acquire()
            self.lease.command(expression=msg.action)
        except LeaseRefused as exc:
            raise ServiceError(f"expression {msg.action.name} refused: {exc}") from None
        self.node.log.info("expression %s set from Foxglove", msg.action.name)
        return msgspec.json.encode(msg)

    def release_expression(self, _request: foxglove.ServiceRequest) -> bytes:
        """Give the expression back to the robot's own behaviour."""
        text = self.lease.release("released from Foxglove")
        reply = m.TriggerReply(success=True, message=text or "no lease was held")
        return msgspec.json.encode(reply)

    def release_idle(self, now: float | None = None) -> None:
        """Give the lease back once no client set the expression for `lease_idle_s`:
        the robot's own behaviour takes it back (the next call takes a new one)."""
        now = time.monotonic() if now is None else now
        self.lease.release_if_idle(now - self._last_call, self.settings.lease_idle_s,
                                   "Foxglove call")

    def close(self) -> None:
        """Give the lease back at stop (were the bridge killed, the controller
        ends it when the node's liveliness token goes)."""
        try:
            self.lease.release("foxglove bridge stopped")
        except ServiceError as exc:
            self.node.log.info("lease not released at stop: %s", clip(exc))

    def play_sound(self, request: foxglove.ServiceRequest) -> bytes:
        """Send a play_sound goal; the reply says whether it was accepted."""
        goal = describe.parse_message(m.PlaySound, _text(request.payload))
        # No audio service, or an error reply: ServiceError, which the SDK sends
        # back to the app as the call's failure message.
        reply = self.node.call(keys.PLAY_SOUND, goal, timeout=CALL_TIMEOUT_S)
        return msgspec.json.encode(reply)


def _text(payload: bytes) -> str:
    try:
        return payload.decode("utf-8")
    except UnicodeDecodeError:
        return "\x00"  # not JSON: parse_message refuses it by name


def gate_of(settings: FoxgloveSettings, upstream_port: int) -> Gate:
    """The gate in front of the SDK's server, from `[foxglove]`; a proxied
    connection holds three descriptors (client, upstream, the SDK's end)."""
    guard = guard_for(settings, settings.host, logging.getLogger("buddybot.foxglove"),
                      per_connection=3)
    return Gate(guard, settings.allowed_origins, upstream_port,
                token_check(settings.host, settings.login))


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    try:
        web_auth.ensure_operator_secret("foxglove bridge")  # its lease is an operator's
    except web_auth.SecretError as exc:
        raise ConfigError(str(exc)) from None
    fox = FoxgloveServer(settings.max_channels)
    gate = gate_of(settings, 0)
    port = gate.start(settings.host, settings.port)  # busy port: ServeError, exit 1
    try:
        gate.upstream_port = fox.start().port  # loopback, a free port: only the gate's
        ctx.alive_checks.append(gate.alive)
        ws, app = urls(settings.host, port)
        print(f"foxglove bridge serving {ws}", flush=True)
        where = "every interface" if is_wildcard(settings.host) else settings.host
        node = ctx.node()
        try:
            node.log.info("Foxglove: connect the app to %s (listening on %s), or open %s",
                          ws, where, app)
            bridge = Bridge(node, fox, settings, gate)
            fox.add_services(bridge.services())
            bridge.subscribe_all()
            LiveSettings(settings, bridge.apply_settings).serve(node)
            manager = threading.Thread(target=bridge.manage, name="foxglove-manager",
                                       daemon=True)
            manager.start()
            node.every(1.0, bridge.update_diagnostics, name="foxglove-diagnostics")
            node.every(0.25, bridge.release_idle, name="foxglove-idle-lease")
            node.spin()
            fox.changed.set()  # wake the manager so it sees the stop
            manager.join(5.0)
            bridge.close()
        finally:
            node.close()
    finally:
        gate.stop()
        fox.stop()
    return 0
