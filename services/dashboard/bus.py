"""The dashboard's side of the bus: subscriptions, timers, button calls.

Everything here runs in Zenoh's or the node's threads and hands results to
the event loop through the `Mailbox` only: newest value per slot, radar
frames appended, at most one wake-up queued and batches >= 20 ms apart, so
a flood of samples costs the loop a bounded amount of work per turn and
never waits for a page.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from buddybot.contract import jpeg, keys
from buddybot.contract import messages as m
from buddybot.dashboard import identity, model, radar_map
from buddybot.dashboard.settings import DashboardSettings
from buddybot.runtime.errors import NoReplyError, ServiceError
from buddybot.runtime.leasing import (
    BROKEN_BY_OPERATOR,
    LeaseHolder,
    LeaseRefused,
    operator_credential,
    release,
)
from buddybot.runtime.limits import clip
from buddybot.runtime.loop_inbox import LoopInbox
from buddybot.runtime.node import Node, RateLimitedLog, Subscription

log = logging.getLogger("buddybot.dashboard")
_warn = RateLimitedLog(log)

CALL_TIMEOUT_S = 3.0
"""How long a button's bus call may take before the page is told it failed."""
PRESENCE_NODE = "radar-presence"
DETECTOR_NODE = "face-detector"
AUDIO_NODE = "audio"
OPERATOR_RESOURCES: list[m.Resource] = ["expression", "gaze", "audio"]
"""What the operator switch takes: the whole robot's face and voice."""
TAKE_CONTROL = "take control first (the operator switch under Actions)"
NODES_REFRESH_S = 2.0
"""Live tokens are asked for at least this often (and at once when one changes)."""

# --- from Zenoh's threads to the loop --------------------------------------------------


class Mailbox(LoopInbox[tuple[str, Any]]):
    """Samples from Zenoh's threads to the event loop (`runtime.loop_inbox`): newest
    per slot, radar frames appended (bounded); batches `min_interval_s` apart."""

    def __init__(self, loop: asyncio.AbstractEventLoop,
                 deliver: Callable[[list[tuple[str, Any]]], None],
                 min_interval_s: float = 0.02) -> None:
        super().__init__(loop, deliver, min_interval_s)
        self._box = model.Outbox()

    def put(self, slot: str, value: Any) -> None:
        with self._lock:
            self.received += 1
            self._box.put(slot, value)
            self._schedule()

    def put_frames(self, frames: list[Any]) -> None:
        with self._lock:
            self.received += 1
            self._box.put_frames(frames)
            self._schedule()

    def _take(self) -> list[tuple[str, Any]]:
        return self._box.take()


# --- the bus side ----------------------------------------------------------------------


class Bus:
    """The node's subscriptions, timers and calls (the node is opened later than
    the web server, in a thread; everything here runs only once it exists)."""

    def __init__(self, node: Node, s: DashboardSettings, mailbox: Mailbox,
                 configured_sounds: dict[str, str]) -> None:
        self.node = node
        self.s = s
        self.mailbox = mailbox
        self.configured_sounds = configured_sounds
        self.limiter = model.RateLimiter(s.max_image_fps)
        self.lease = LeaseHolder(node, OPERATOR_RESOURCES, "operator", CALL_TIMEOUT_S)
        self._leases: m.Leases | None = None
        self._leases_lock = threading.Lock()
        self._nodes_wanted = threading.Event()
        self._nodes_wanted.set()
        self._last_nodes = 0.0
        self.images_bad = 0
        self.image_sub: Subscription | None = None
        self._subscribe()

    def apply(self, s: DashboardSettings) -> None:
        """A live settings change (a node worker thread): the image rate and JPEG
        quality hold from the next image; the rest is read where it is used."""
        self.limiter.set_rate(s.max_image_fps)
        self.s = s

    def _subscribe(self) -> None:
        node, box = self.node, self.mailbox

        def latest(slot: str) -> Callable[[Any, str], None]:
            return lambda msg, _key: box.put(slot, msg)

        def on_radar(msg: m.LD2410TargetDataFrameArray, _key: str) -> None:
            box.put_frames([(msg.stamp_ns / 1e9, msg)])

        def on_targets(msg: m.RadarTargets, _key: str) -> None:
            box.put(f"targets:{msg.device_id}/{msg.radar_id}", msg)

        def on_direction(msg: m.EyesDirection, _key: str) -> None:
            box.put("direction", (msg, (time.time_ns() - msg.stamp_ns) / 1e6))

        def on_diag(msg: m.DiagnosticStatus, _key: str) -> None:
            box.put(f"diag:{msg.node}", msg)

        node.subscribe(keys.RADAR_FRAMES, on_radar, device="*")
        node.subscribe(keys.RADAR_TARGETS, on_targets, device="*")
        node.subscribe(keys.PRESENCE, latest("presence"))
        node.subscribe(keys.PEOPLE_STATE, latest("people"))
        node.subscribe(keys.FACES, latest("faces"), camera=self.s.camera)
        node.subscribe(keys.CONTROLLER_STATE, latest("controller"))
        node.subscribe(keys.EXPRESSION, latest("expression"))
        node.subscribe(keys.LEASES, self._on_leases)
        node.subscribe(keys.EYES_DIRECTION, on_direction)
        node.subscribe(keys.PUPIL, latest("pupil"))
        node.subscribe(keys.LIDS, latest("lids"))
        node.subscribe(keys.DIAGNOSTICS, on_diag, node="*")
        node.subscribe(keys.SIM_WORLD, latest("truth"))  # only while simulating
        node.watch_node("*", lambda _instances: self._nodes_wanted.set())
        node.every(0.1, self._refresh_nodes, name="nodes")
        node.every(self.s.params_period_s, self.refresh_params, name="params")
        threading.Thread(target=self.refresh_params, name="dashboard:params0",
                         daemon=True).start()

    # -- nodes and parameters (timer threads) --

    def _refresh_nodes(self) -> None:
        """Ask for every live token when one came or went (and every few seconds)."""
        due = time.monotonic() - self._last_nodes > NODES_REFRESH_S
        if not (self._nodes_wanted.is_set() or due):
            return
        self._nodes_wanted.clear()
        self._last_nodes = time.monotonic()
        self.mailbox.put("live", self.node.node_instances(timeout=1.0))

    def _params(self, node_name: str, request: m.ParamRequest) -> m.ParamReply | None:
        try:
            reply: m.ParamReply = self.node.call(keys.PARAMS, request, timeout=1.0,
                                                 node=node_name)
            return reply
        except ServiceError:
            return None

    def refresh_params(self) -> None:
        reply = self._params(PRESENCE_NODE, m.ParamRequest(op="list"))
        self.mailbox.put("rules", None if reply is None else model.presence_rules(reply))
        self.mailbox.put("zones", radar_map.parse_zones(radar_map.params_value(reply, "zones")))
        camera = self._params(DETECTOR_NODE, m.ParamRequest(op="list"))
        self.mailbox.put("camera_params", None if camera is None or camera.error
                         else radar_map.number_params(camera, radar_map.CAMERA_FIELDS))
        sounds = self._params(AUDIO_NODE, m.ParamRequest(op="get", name="sounds"))
        self.mailbox.put("sounds", model.sound_names(sounds, self.configured_sounds))

    # -- images --

    def watch_images(self, on: bool) -> None:
        """Subscribe to the camera only while a page is connected."""
        if on and self.image_sub is None:
            self.image_sub = self.node.subscribe(
                keys.CAMERA_IMAGE, self._on_image, delivery="latest", camera=self.s.camera)
            log.info("watching camera/%s/image", self.s.camera)
        elif not on and self.image_sub is not None:
            self.image_sub.close()
            self.image_sub = None
            log.info("no page left: camera images unsubscribed")

    def _on_image(self, msg: m.Image, _key: str) -> None:
        """On the subscription's worker: at most max_image_fps JPEGs, quality from settings."""
        if not self.limiter.allow(time.monotonic()):
            return
        try:
            data = jpeg.from_image(msg, self.s.jpeg_quality)
        except jpeg.PixelsError:
            self.images_bad += 1
            _warn.warning("image", "dropped a bgr8 image of %d bytes (%dx%d needs %d)",
                          len(msg.data), msg.width, msg.height, msg.width * msg.height * 3)
            return
        if data is None:
            self.images_bad += 1
            return
        self.mailbox.put("image", model.pack_image(model.image_header(msg), data))

    # -- leases --

    def _on_leases(self, msg: m.Leases, _key: str) -> None:
        """`leases/state` (Zenoh's thread): our lease is forgotten once it is gone."""
        with self._leases_lock:
            self._leases = msg
            self.lease.forget_unless_in(msg)
            self._post_leases()

    def _post_leases(self) -> None:
        self.mailbox.put("leases", (self._leases, self.lease.public_id))  # never the handle

    def _leases_changed(self) -> None:
        with self._leases_lock:
            self._post_leases()

    def close(self) -> None:
        """Give the operator lease back when the dashboard stops (were it killed,
        the controller ends it when the node's liveliness token goes)."""
        try:
            self.lease.release("dashboard stopped")
        except ServiceError as exc:
            log.info("operator lease not released at stop: %s", clip(exc, 200))

    # -- buttons (called in a worker thread) --

    def run_command(self, cmd: model.Command) -> tuple[bool, str]:
        """One page request on the bus: (ok, the text the page shows)."""
        if isinstance(cmd, model.Control):
            return self._control(cmd.on)
        if isinstance(cmd, model.BreakLease):
            return self._break(cmd.lease_id)
        if isinstance(cmd, identity.ListKnown):
            return self._identity(cmd)
        if self.lease.lease_id is None:
            return False, TAKE_CONTROL
        if isinstance(cmd, (identity.EnrolFace, identity.ForgetFace)):
            return self._identity(cmd)
        if isinstance(cmd, model.SetExpression):
            action = m.ExpressionAction[cmd.action]
            return _lease_call(f"expression {action.name}",
                               lambda: self.lease.command(expression=action))
        if isinstance(cmd, model.Look):
            return _lease_call(f"look {cmd.yaw:+.2f} / {cmd.pitch:+.2f} rad",
                               lambda: self.lease.command(yaw=cmd.yaw, pitch=cmd.pitch))
        return self._audio(cmd)

    def _identity(self, cmd: identity.Request) -> tuple[bool, str]:
        ok, text, known = identity.run(self.node, cmd)
        if known is not None:
            self.mailbox.put("known", known)
        return ok, text

    def release_idle(self, quiet_s: float) -> bool:
        """Give the operator's lease back when no page was open for `lease_idle_s`
        (`quiet_s` so far); True when it was given back."""
        if not self.lease.release_if_idle(quiet_s, self.s.lease_idle_s, "dashboard page"):
            return False
        self._leases_changed()
        return True

    def _control(self, on: bool) -> tuple[bool, str]:
        if on:
            ok, text = _lease_call("take control", lambda: _granted(
                m.public_lease_id(self.lease.acquire())))
        else:
            ok, text = _lease_call("give back control",
                                   lambda: self.lease.release("released by operator")
                                   or "control was not held")
        self._leases_changed()
        return ok, text

    def _break(self, lease_id: str) -> tuple[bool, str]:
        if lease_id == self.lease.public_id:
            ok, text = _lease_call(f"break {clip(lease_id, 64)}",
                                   lambda: self.lease.release(BROKEN_BY_OPERATOR) or "")
        else:
            ok, text = _lease_call(f"break {clip(lease_id, 64)}", lambda: release(
                self.node, lease_id, BROKEN_BY_OPERATOR, CALL_TIMEOUT_S,
                credential=operator_credential()))
        self._leases_changed()
        return ok, text

    def _audio(self, cmd: model.PlaySound | model.StopSound) -> tuple[bool, str]:
        if isinstance(cmd, model.PlaySound):
            try:
                reply: m.PlaySoundReply = self.node.call(
                    keys.PLAY_SOUND, m.PlaySound(sound=cmd.sound), timeout=CALL_TIMEOUT_S)
            except ServiceError as exc:
                return False, f"play {clip(cmd.sound, 60)}: {clip(exc, 200)}"
            if reply.accepted:
                return True, f"playing {clip(cmd.sound, 60)} (goal {reply.goal_id})"
            return False, f"{clip(cmd.sound, 60)} refused: {clip(reply.message, 200)}"
        try:
            stopped: m.TriggerReply = self.node.call(keys.AUDIO_STOP, m.Trigger(),
                                                     timeout=CALL_TIMEOUT_S)
        except ServiceError as exc:
            return False, f"stop: {clip(exc, 200)}"
        return stopped.success, stopped.message or ("stopped" if stopped.success else "refused")


def _granted(lease_id: str) -> str:
    return f"lease {lease_id} on {', '.join(OPERATOR_RESOURCES)}"


def _lease_call(what: str, call: Callable[[], str]) -> tuple[bool, str]:
    """A lease call's outcome as the page shows it: refusals with the arbiter's
    reason, a missing eyes driver said plainly (every call is bounded in time)."""
    try:
        text = call()
    except LeaseRefused as exc:
        return False, f"{what} refused: {clip(exc, 200)}"
    except NoReplyError:
        return False, f"{what}: the eyes driver does not answer (is it running?)"
    except ServiceError as exc:
        return False, f"{what}: {clip(exc, 200)}"
    return True, f"{what}: {clip(text, 200)}" if text else what
