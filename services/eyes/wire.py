"""What the renderer sends to its pages, pure: no web server, no Zenoh.

Each WebSocket text message is `{"topic": T, "msg": M}` with M in the
contract's field names (docs/design.md section 3), so the page reads the same
fields as every other consumer. `LatestState` keeps the newest message per
slot so a page that (re)connects gets the whole current state at once,
and the same type serves as each client's coalescing outbox: a slow page
gets the newest gaze, never a growing backlog.

It also holds the WebSocket origin rule (`origin_allowed`), pure so it is
tested without a server, and the two messages of "one face, many screens"
(docs/eyes.md): `motion` (a blink or saccade every page draws at the same
server time; the newest of each kind is kept in the state, so a page that
connects late joins the motion under way) and the clock ping/pong a page
uses to learn the server clock.
"""

from __future__ import annotations

import ipaddress
import math
from collections.abc import Collection, Iterable
from typing import Any
from urllib.parse import urlsplit

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


# --- who may open the WebSocket ------------------------------------------------------

_DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}


def _origin_key(scheme: str, netloc: str) -> tuple[str, int] | None:
    """(host, port) of `netloc` under `scheme`, lower-case; None if unparsable."""
    try:
        parts = urlsplit(f"{scheme}://{netloc}")
        port = parts.port
    except ValueError:
        return None
    if not parts.hostname or parts.username is not None or parts.password is not None:
        return None
    return parts.hostname.lower(), port if port is not None else _DEFAULT_PORTS[scheme]


def _is_ip(hostname: str) -> bool:
    try:
        ipaddress.ip_address(hostname)
    except ValueError:
        return False
    return True


def origin_allowed(origin: str | None, host: str | None, allowed: Iterable[str] = (),
                   names: Collection[str] | None = None) -> bool:
    """Whether a WebSocket request from `origin` to the server reached as `host`
    (its Host header) may connect.

    Browsers send Origin with every WebSocket and a page from another site
    can open one to 127.0.0.1, so only the server's own origin (same host
    and port as the request went to) and the configured `allowed` origins
    pass. With `names`, the own origin must also name this machine (an IP
    address or one of `names`): a site whose DNS name was pointed at the
    robot (DNS rebinding) has matching Origin and Host, but not our name.
    No Origin at all is a program, not a browser page: allowed (it could
    open any socket anyway). "null" (sandboxed frames, files) passes only
    when listed.
    """
    if origin is None:
        return True
    origin = origin.strip()
    if origin in allowed:
        return True
    if origin == "null":
        return False
    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    scheme = parts.scheme.lower()
    if scheme not in ("http", "https") or parts.path not in ("", "/") or parts.query:
        return False
    key = _origin_key(scheme, parts.netloc)
    if key is None:
        return False
    for listed in allowed:
        try:
            listed_parts = urlsplit(listed)
        except ValueError:
            continue
        if listed_parts.scheme.lower() == scheme and _origin_key(
                scheme, listed_parts.netloc) == key:
            return True
    if host is None or _origin_key(scheme, host.strip()) != key:
        return False
    return names is None or _is_ip(key[0]) or key[0] in names
