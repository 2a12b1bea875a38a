"""The live status line of `buddybot up`: what an operator wants at a glance.

`RobotStatus` is fed by a small probe node (liveliness, presence,
face, radar frame rate, expression) and formatted by a pure function, so
the wording is tested without a robot. Images are deliberately not
subscribed to: the camera's rate comes from its diagnostics, which costs
nothing, instead of pulling 30 raw frames a second into the launcher.
The probe declares no liveliness token, so it is not one of the nodes it
counts.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node, Subscription
from buddybot.runtime.rates import rate_hz


@dataclass
class RobotStatus:
    expected: list[str]
    up: list[str] = field(default_factory=list)
    duplicates: list[str] = field(default_factory=list)
    """Node names with more than one live instance (two robots on one bus?)."""
    radar_arrivals: deque[float] = field(default_factory=lambda: deque(maxlen=50))
    presence: m.PresenceDetection | None = None
    face_distance_m: float | None = None
    face_seen_at: float = 0.0
    expression: m.ExpressionAction | None = None
    camera_fps: float | None = None
    restarts: int = 0
    given_up: dict[str, int | None] = field(default_factory=dict)
    """Services `up` will not restart (name -> exit status): down, whatever the bus
    says (a node of that name alive elsewhere is not ours)."""


def format_status(status: RobotStatus, now: float) -> str:
    """One line, e.g. `nodes 9/9 | radar 10.0 Hz | presence IN_RANGE 1.20 m | ...`."""
    missing = [n for n in status.expected if n not in status.up or n in status.given_up]
    nodes = f"nodes {len(status.expected) - len(missing)}/{len(status.expected)}"
    if missing:
        nodes += f" (down: {', '.join(missing)})"
    if status.given_up:
        nodes += " (not restarted: " + ", ".join(
            f"{n} exit {code}" for n, code in sorted(status.given_up.items())) + ")"
    if status.duplicates:
        nodes += f" (DUPLICATE: {', '.join(status.duplicates)})"
    parts = [nodes, f"radar {rate_hz(status.radar_arrivals, now):.1f} Hz"]
    if status.camera_fps is not None:
        parts.append(f"camera {status.camera_fps:.1f} fps")
    if status.presence is None:
        parts.append("presence ?")
    else:
        p = status.presence
        parts.append(f"presence {p.presence_state.name} {p.distance_m:.2f} m")
    if status.face_distance_m is not None and now - status.face_seen_at < 2.0:
        parts.append(f"face {status.face_distance_m:.2f} m")
    else:
        parts.append("face -")
    parts.append(f"eyes {status.expression.name if status.expression is not None else '?'}")
    if status.restarts:
        parts.append(f"restarts {status.restarts}")
    return " | ".join(parts)


class StatusMonitor:
    """Keeps a RobotStatus up to date from the robot's own traffic.

    `node` should be a probe (`Node(..., probe=True)`) of the robot to watch;
    the monitor closes its own subscriptions, the caller the node.
    """

    def __init__(self, node: Node, expected: list[str]) -> None:
        self.status = RobotStatus(expected=expected)
        self.node = node
        self._lock = threading.Lock()
        self._subs: list[Subscription] = []
        self._watch(keys.RADAR_FRAMES, self._on_radar)
        self._watch(keys.RADAR_TARGETS, self._on_radar)
        self._watch(keys.PRESENCE, self._on_presence)
        self._watch(keys.FACE, self._on_face)
        self._watch(keys.EXPRESSION, self._on_expression)
        self._watch(keys.DIAGNOSTICS, self._on_diagnostics)

    def _watch(self, topic: keys.Topic, handler: Callable[[Any], None]) -> None:
        # Raw, decoded here: bad traffic is the services' business, not the
        # launcher's (no warnings, no counters). Latched values come at once.
        key = self.node.key(topic)
        codec, msg_type = topic.codec, topic.type

        def on_sample(_key: str, payload: bytes, _encoding: str) -> None:
            try:
                msg = codec.decode(payload, msg_type)
            except Exception:
                return
            with self._lock:
                handler(msg)

        self._subs.append(self.node.subscribe_raw(key, on_sample, history=topic.latched))

    def _on_radar(self, _msg: m.LD2410TargetDataFrameArray | m.RadarTargets) -> None:
        """A report of either radar model: the rate says the radars are alive."""
        self.status.radar_arrivals.append(time.monotonic())

    def _on_presence(self, msg: m.PresenceDetection) -> None:
        self.status.presence = msg

    def _on_face(self, msg: m.FacePosition) -> None:
        p = msg.point
        self.status.face_distance_m = math.sqrt(p.x * p.x + p.y * p.y + p.z * p.z)
        self.status.face_seen_at = time.monotonic()

    def _on_expression(self, msg: m.ScreenExpression) -> None:
        self.status.expression = msg.action

    def _on_diagnostics(self, msg: m.DiagnosticStatus) -> None:
        if msg.node == "camera":
            fps = msg.values.get("fps")
            if isinstance(fps, int | float):
                self.status.camera_fps = float(fps)

    def line(self, restarts: int, given_up: dict[str, int | None] | None = None) -> str:
        """The status line now; `given_up`: services that exited for good."""
        found = self.node.node_instances(timeout=1.0)
        with self._lock:
            self.status.up = sorted(found)
            self.status.given_up = dict(given_up or {})
            self.status.duplicates = sorted(n for n, ids in found.items() if len(ids) > 1)
            self.status.restarts = restarts
            return format_status(self.status, time.monotonic())

    def close(self) -> None:
        """Stop watching (the node stays open: it belongs to the caller)."""
        for sub in self._subs:
            sub.close()
