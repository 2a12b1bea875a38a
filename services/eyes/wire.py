"""What the renderer sends to its pages, pure: no web server, no Zenoh.

Each WebSocket text message is `{"topic": T, "msg": M}` with M in the
contract's field names (docs/design.md section 3), so the page reads the same
fields as every other consumer. `LatestState` keeps the newest message per
slot so a page that (re)connects gets the whole current state at once,
and the same type serves as each client's coalescing outbox: a slow page
gets the newest gaze, never a growing backlog.

It also holds the two messages of "one face, many screens"
(docs/eyes.md): `motion` (a blink or saccade every page draws at the same
server time; the newest of each kind is kept in the state, so a page that
connects late joins the motion under way) and the clock ping/pong a page
uses to learn the server clock.
"""

from __future__ import annotations

import math
from typing import Any

import msgspec

from buddybot.contract import messages as m
from buddybot.eyes.styles import Style

TOPIC_NAMES: dict[type[m.Message], str] = {
    m.EyesDirection: "direction",
    m.PupilControl: "pupil",
    m.EyeLidControl: "lids",
    m.ScreenExpression: "expression",
}

_encoder = msgspec.json.Encoder()


class Hello(msgspec.Struct, kw_only=True):
    """First message on every connection: how the page should look.

    `style` is the whole chosen style, every expression's pose resolved
    (styles.py), so the page needs no other file and a live change is one
    new hello; None: the page keeps the style it has (its built-in fallback
    at first)."""

    iris_color: str
    max_yaw_deg: float
    max_pitch_deg: float
    server_id: str
    style: Style | None = None


class Status(msgspec.Struct, kw_only=True):
    """Whether the renderer is on the bus (connected to a Zenoh router).

    Sent in every page's first batch and again on each change: without the
    bus no state can arrive, so the page shows its calm "connecting" face
    instead of pretending to look at someone.
    """

    bus: bool


class Pong(msgspec.Struct, kw_only=True):
    """The answer to a page's `{"topic": "ping", "msg": {"t0": T}}`: its own `t0`
    back and the server clock (ms since the epoch) when the ping arrived.
    The page takes the round trip with the smallest delay (NTP-style)."""

    t0: float
    server_ms: float


PING_MAX_BYTES = 200
"""A ping is ~40 bytes; anything longer is not one and is not parsed."""


def parse_ping(text: str) -> float | None:
    """The `t0` of a page's ping, or None for anything else (ignored, never raises)."""
    if len(text) > PING_MAX_BYTES:
        return None
    try:
        data = msgspec.json.decode(text)
    except msgspec.DecodeError:
        return None
    if not isinstance(data, dict) or data.get("topic") != "ping":
        return None
    msg = data.get("msg")
    t0 = msg.get("t0") if isinstance(msg, dict) else None
    if isinstance(t0, bool) or not isinstance(t0, int | float) or not math.isfinite(t0):
        return None
    return float(t0)


def motion_slot(kind: str) -> str:
    """The state slot of a motion event: the newest blink and the newest saccade."""
    return f"motion:{kind}"


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
