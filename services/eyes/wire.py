"""What the renderer sends to its pages, pure: no web server, no Zenoh.

Each WebSocket text message is `{"topic": T, "msg": M}` with M in the
contract's field names (DESIGN.md section 2), so the page reads the same
fields as every other consumer. `LatestState` keeps the newest message per
slot so a page that (re)connects gets the whole current state at once,
and the same type serves as each client's coalescing outbox: a slow page
gets the newest gaze, never a growing backlog.
"""

from __future__ import annotations

from typing import Any

import msgspec

from buddybot.core import messages as m

TOPIC_NAMES: dict[type[m.Message], str] = {
    m.EyesDirection: "direction",
    m.PupilControl: "pupil",
    m.EyeLidControl: "lids",
    m.ScreenExpression: "expression",
}

_encoder = msgspec.json.Encoder()


class Hello(msgspec.Struct, kw_only=True):
    """First message on every connection: how the page should look."""

    iris_color: str
    max_yaw_deg: float
    max_pitch_deg: float
    server_id: str


def encode(topic: str, msg: Any) -> str:
    return _encoder.encode({"topic": topic, "msg": msg}).decode()


def slot(msg: m.Message) -> str:
    """The state slot a message replaces: one per topic, lids one per eye id."""
    name = TOPIC_NAMES[type(msg)]
    if isinstance(msg, m.EyeLidControl):
        return f"lids:{int(msg.eye_id)}"
    return name


class LatestState:
    """Newest encoded message per slot, in the order they must be applied."""

    def __init__(self) -> None:
        self._slots: dict[str, str] = {}

    def put(self, slot_name: str, text: str) -> None:
        # Re-inserting moves the slot to the end: application order follows
        # arrival order, so a later per-eye lid message wins over an earlier
        # BOTH and vice versa.
        self._slots.pop(slot_name, None)
        if slot_name == f"lids:{int(m.EyeId.BOTH)}":
            for eye in (m.EyeId.LEFT, m.EyeId.RIGHT):
                self._slots.pop(f"lids:{int(eye)}", None)
        self._slots[slot_name] = text

    def put_message(self, msg: m.Message) -> str:
        text = encode(TOPIC_NAMES[type(msg)], msg)
        self.put(slot(msg), text)
        return text

    def take(self) -> list[str]:
        """All messages, oldest first, and empty the state (outbox use)."""
        items = list(self._slots.values())
        self._slots.clear()
        return items

    def snapshot(self) -> list[str]:
        return list(self._slots.values())

    def items(self) -> list[tuple[str, str]]:
        return list(self._slots.items())

    def __len__(self) -> int:
        return len(self._slots)
