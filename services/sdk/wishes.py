"""`bot.wishes`: the eyes at the lowest priority, for the robot's own behaviour.

The built-in behaviour is the one client of the eyes driver's arbiter that
never needs a lease: what it wishes is what the robot shows whenever no
lease holds that part (docs/design.md, leases). It is therefore never
refused and never rate limited, and there is exactly one such client: a
`Bot` made for the built-in behaviour (`buddybot.sdk.service`) has wishes,
an app's `Bot` has `bot.eyes`.
"""

from __future__ import annotations

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk.eyes import expression_of, gaze_of


class Wishes:
    """The built-in behaviour's expression (latched) and gaze, to the arbiter."""

    def __init__(self, node: Node) -> None:
        self._expression = node.publisher(keys.BEHAVIOUR_EXPRESSION)
        self._gaze = node.publisher(keys.BEHAVIOUR_GAZE)

    def express(self, expression: m.ExpressionAction | str) -> None:
        """Wish for `expression` (a name, alias or `ExpressionAction`)."""
        self._expression.put(m.ScreenExpression(stamp_ns=m.now_ns(),
                                                action=expression_of(expression)))

    def look_at(self, yaw: float, pitch: float, distance_m: float | None = None,
                stamp_ns: int | None = None) -> None:
        """Wish for a gaze (radians, + = left / up; ValueError out of range).
        `stamp_ns`: the capture time of what it follows (a face's), so the
        latency from camera to eyes can be read at the eyes; default now."""
        g_yaw, g_pitch, distance_cm = gaze_of(yaw, pitch, distance_m)
        self._gaze.put(m.EyeControl(stamp_ns=m.now_ns() if stamp_ns is None else stamp_ns,
                                    yaw=g_yaw, pitch=g_pitch,
                                    target_distance_cm=distance_cm))
