"""The live status line of `buddybot up`: what an operator wants at a glance.

`RobotStatus` is fed by a small monitor session (liveliness, presence,
face, radar frame rate, expression) and formatted by a pure function, so
the wording is tested without a robot. Images are deliberately not
subscribed to: the camera's rate comes from its diagnostics, which costs
nothing, instead of pulling 30 raw frames a second into the launcher.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import zenoh

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.rates import rate_hz
from buddybot.core.tools import list_node_instances


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


def format_status(status: RobotStatus, now: float) -> str:
    """One line, e.g. `nodes 9/9 | radar 10.0 Hz | presence IN_RANGE 1.20 m | ...`."""
    missing = [n for n in status.expected if n not in status.up]
    nodes = f"nodes {len(status.expected) - len(missing)}/{len(status.expected)}"
    if missing:
        nodes += f" (down: {', '.join(missing)})"
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
    """Keeps a RobotStatus up to date from the robot's own traffic."""

    def __init__(self, session: zenoh.Session, robot: str, expected: list[str]) -> None:
        self.status = RobotStatus(expected=expected)
        self._session = session
        self._robot = robot
        self._lock = threading.Lock()
        self._subs: list[object] = []
        self._watch(keys.RADAR_FRAMES, self._on_frames)
        self._watch(keys.PRESENCE, self._on_presence)
        self._watch(keys.FACE, self._on_face)
        self._watch(keys.EXPRESSION, self._on_expression)
        self._watch(keys.DIAGNOSTICS, self._on_diagnostics)

    def _watch(self, topic: keys.Topic, handler: object) -> None:
        key = keys.absolute(self._robot, topic.wildcard())
        codec, msg_type = topic.codec, topic.type

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                msg = codec.decode(sample.payload.to_bytes(), msg_type)
            except Exception:  # bad traffic is the services' business, not the launcher's
                return
            with self._lock:
                handler(msg)  # type: ignore[operator]

        self._subs.append(self._session.declare_subscriber(key, on_sample))

    def _on_frames(self, _msg: m.LD2410TargetDataFrameArray) -> None:
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

    def line(self, restarts: int) -> str:
        found = list_node_instances(self._session, self._robot, timeout=1.0)
        with self._lock:
            self.status.up = sorted(found)
            self.status.duplicates = sorted(n for n, ids in found.items() if len(ids) > 1)
            self.status.restarts = restarts
            return format_status(self.status, time.monotonic())

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()  # type: ignore[attr-defined]
