"""`bot.on_face`: the faces a camera's detector follows, as they come.

A face is the robot's fastest signal (camera -> eyes), so the callback runs
on the thread that receives it, with no queue in between: keep it quick,
and hand slow work to a thread of your own. The robot's own gaze is
decided here, which is why this is a callback and not a stream.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.handles import Subscription
from buddybot.runtime.node import Node

log = logging.getLogger("buddybot.sdk")


@dataclass(frozen=True, slots=True)
class Face:
    """One face's centre in the camera's frame (metres: x ahead, y left, z up)."""

    x_m: float
    y_m: float
    z_m: float
    stamp_ns: int
    """When the frame that showed it was captured (the camera's clock)."""
    confidence: float
    track: int | None = None
    """Whose face this is as the detector follows them (None: a source without ids)."""
    camera: str = ""


def face_from(msg: m.FacePosition, camera: str) -> Face:
    p = msg.point
    return Face(x_m=p.x, y_m=p.y, z_m=p.z, stamp_ns=msg.stamp_ns,
                confidence=msg.confidence, track=msg.track, camera=camera)


def on_face(node: Node, camera: str, callback: Callable[[Face], Any]) -> Subscription:
    """Call `callback(face)` for every face `camera` publishes until the returned
    subscription is closed; a failing callback is logged, never fatal."""
    if not keys.valid_robot_id(camera):
        raise ValueError(f"{camera!r} is not a camera name")

    def deliver(msg: m.FacePosition, _key: str) -> None:
        try:
            callback(face_from(msg, camera))
        except Exception:
            log.exception("face callback %r failed", callback)

    return node.subscribe(keys.FACE, deliver, camera=camera)
