"""What the dashboard remembers and decides, without Zenoh, threads or sockets.

The server (`service.py`) feeds these classes the messages it receives and
a clock value; everything here is deterministic and tested on its own
(tests/dashboard/test_model.py):

* `History`: the radar distances of the last `history_s` seconds, so a page
  that opens late still draws the whole plot;
* `RateLimiter`: at most N camera images per second to the pages, on
  average, without bursts (JPEG encoding is the dashboard's main CPU cost);
* `NodeTable`: alive/down per node from liveliness tokens, restarts counted
  when a node comes back under a new instance id, last diagnostics; the
  nodes the config runs stay listed when down, the others leave;
* `Latency`: capture-to-gaze latency percentiles over a sliding window;
* `Outbox`: what one page has not been sent yet (newest per slot, radar
  frames appended), so a slow page never builds a backlog;
* `parse_command`: a page's request (take or give back control, set an
  expression, look, play, stop, break a lease), validated, or a one-line
  error for the page;
* `leases_view`: `leases/state` as the lease panel shows it, the
  dashboard's own lease marked;
* `presence_rules`, `sound_names`, `eye_page_url`: small
  conversions with rules worth testing.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Annotated, Any
from urllib.parse import urlsplit

import msgspec

from buddybot.contract import messages as m
from buddybot.dashboard import identity
from buddybot.runtime.limits import BoundedDict, clip

MAX_NODES = 256
"""Node names remembered (liveliness keys are chosen by whoever connects)."""
GONE_AFTER_S = 10.0
"""A node the config does not run (an app started by hand, a tool) is dropped from
the list this long after it went down: long enough to see it stop, and `up`
restarts a crashed child sooner (1 s), so a restart keeps its row."""
MAX_SENSORS = 32
"""Radar sensors (device, radar id) remembered."""
MAX_QUEUED_FRAMES = 200
"""Radar frames kept for one page that has not read them yet (20 s at 10 Hz)."""


# --- radar history -------------------------------------------------------------------


class History:
    """(t_s, moving_cm, still_cm) points of one sensor over the last `span_s` seconds."""

    def __init__(self, span_s: float) -> None:
        self.span_s = span_s
        self._points: deque[tuple[float, int, int]] = deque()

    def add(self, t_s: float, moving_cm: int, still_cm: int) -> None:
        if self._points and t_s < self._points[-1][0]:
            t_s = self._points[-1][0]  # never go back in time (a late frame joins the end)
        self._points.append((t_s, moving_cm, still_cm))
        self.trim(t_s)

    def trim(self, now_s: float) -> None:
        while self._points and self._points[0][0] < now_s - self.span_s:
            self._points.popleft()

    def points(self) -> list[tuple[float, int, int]]:
        return list(self._points)

    def __len__(self) -> int:
        return len(self._points)


class RadarHistory:
    """A `History` per sensor, keyed `"<device>/<radar_id>"`, bounded in number."""

    def __init__(self, span_s: float, max_sensors: int = MAX_SENSORS) -> None:
        self.span_s = span_s
        self._sensors: BoundedDict[str, History] = BoundedDict(max_sensors)

    def add(self, t_s: float, frames: m.LD2410TargetDataFrameArray) -> None:
        for sensor in frames.sensors:
            key = sensor_key(frames.device_id, sensor.radar_id)
            history = self._sensors.get(key)
            if history is None:
                history = self._sensors[key] = History(self.span_s)
            history.add(t_s, sensor.movement_distance, sensor.stationary_distance)

    def snapshot(self, now_s: float) -> dict[str, list[tuple[float, int, int]]]:
        out = {}
        for key, history in self._sensors.items():
            history.trim(now_s)
            out[key] = history.points()
        return out


def sensor_key(device_id: int, radar_id: int) -> str:
    return f"{device_id}/{radar_id}"


def radar_view(t_s: float, frames: m.LD2410TargetDataFrameArray) -> list[dict[str, Any]]:
    """One entry per sensor, as the page draws it (engineering fields None in basic mode)."""
    out = []
    for s in frames.sensors:
        out.append({
            "sensor": sensor_key(frames.device_id, s.radar_id), "t": t_s,
            "state": s.target_state.name, "moving_cm": s.movement_distance,
            "moving_energy": s.movement_energy, "still_cm": s.stationary_distance,
            "still_energy": s.stationary_energy, "detection_cm": s.detection_distance,
            "moving_gates": s.moving_gate_energy, "still_gates": s.stationary_gate_energy,
            "max_moving_gate": s.max_moving_gate, "max_still_gate": s.max_stationary_gate,
            "light": s.light_level,
        })
    return out


# --- images --------------------------------------------------------------------------


class RateLimiter:
    """At most `rate` events per second on average, never a burst.

    Each allowed event moves the next due time one interval on, from the
    previous due time (so 15 fps in, 10 fps limit gives 10 fps out, not the
    7.5 a plain "at least 100 ms apart" rule gives) but never from further
    back than one interval (so a pause does not buy a burst afterwards).
    """

    def __init__(self, rate: float) -> None:
        self.interval = 1.0
        self.set_rate(rate)
        self._due = -math.inf
        self.allowed = 0
        self.refused = 0

    def set_rate(self, rate: float) -> None:
        """A new limit, from the next event on (a live parameter change)."""
        if not rate > 0:
            raise ValueError("rate must be > 0")
        self.interval = 1.0 / rate

    def allow(self, now: float) -> bool:
        # A hair of tolerance: frames at exactly the limit's rate arrive with jitter.
        if now + 0.1 * self.interval < self._due:
            self.refused += 1
            return False
        self._due = max(self._due, now - self.interval) + self.interval
        self.allowed += 1
        return True


def image_header(msg: m.Image) -> dict[str, Any]:
    return {"stamp_ns": msg.stamp_ns, "frame_id": msg.frame_id,
            "width": msg.width, "height": msg.height}


def pack_image(header: dict[str, Any], jpeg: bytes) -> bytes:
    """One binary WebSocket frame: 4-byte big-endian header length, JSON header, JPEG."""
    head = msgspec.json.encode(header)
    return len(head).to_bytes(4, "big") + head + jpeg


def unpack_image(frame: bytes) -> tuple[dict[str, Any], bytes]:
    """The inverse of `pack_image` (for tests and tools)."""
    size = int.from_bytes(frame[:4], "big")
    header: dict[str, Any] = msgspec.json.decode(frame[4:4 + size])
    return header, frame[4 + size:]


# --- nodes ---------------------------------------------------------------------------


@dataclass
class NodeRow:
    name: str
    instances: frozenset[str] = frozenset()
    seen: set[str] = field(default_factory=set)
    """Every instance id this name ever had (a new one is a restart)."""
    restarts: int = 0
    since_s: float = 0.0
    """When it last came up or went down."""
    level: str | None = None
    message: str = ""
    diag_s: float | None = None

    @property
    def alive(self) -> bool:
        return bool(self.instances)

    def view(self) -> dict[str, Any]:
        return {"name": self.name, "alive": self.alive, "instances": sorted(self.instances),
                "restarts": self.restarts, "since": self.since_s, "level": self.level,
                "message": self.message, "diag_t": self.diag_s}


class NodeTable:
    """Every node seen: alive or down, restarts, its last diagnostics.

    `update` takes the complete set of live tokens (name -> instance ids),
    as a liveliness query answers it. A node the config runs (`keep`: its
    enabled services and apps) that disappears stays listed as down, since
    it should be running; any other node is dropped `gone_after_s` after it
    went down (an app that stopped has left, it is not broken). One that
    comes back under an instance id it never had before counts a restart
    (a second instance next to a live one counts too: it is a new process
    under that name). Names are bounded (oldest forgotten).
    """

    def __init__(self, max_nodes: int = MAX_NODES, keep: frozenset[str] = frozenset(),
                 gone_after_s: float = GONE_AFTER_S) -> None:
        self._rows: BoundedDict[str, NodeRow] = BoundedDict(max_nodes)
        self.keep = keep
        self.gone_after_s = gone_after_s

    def _row(self, name: str, now_s: float) -> NodeRow:
        row = self._rows.get(name)
        if row is None:
            row = self._rows[name] = NodeRow(name=name, since_s=now_s)
        return row

    def update(self, live: dict[str, set[str]], now_s: float) -> bool:
        """Apply a complete liveliness snapshot; True when anything shown changed."""
        changed = False
        for name, instances in live.items():
            row = self._row(name, now_s)
            current = frozenset(instances)
            if current == row.instances:
                continue
            new = current - row.seen
            if row.seen and new:
                row.restarts += len(new)
            if bool(current) != row.alive:
                row.since_s = now_s
            row.seen |= current
            row.instances = current
            changed = True
        for name, row in self._rows.items():
            if name not in live and row.alive:
                row.instances = frozenset()
                row.since_s = now_s
                changed = True
        gone = [name for name, row in self._rows.items() if not row.alive
                and name not in self.keep and now_s - row.since_s >= self.gone_after_s]
        for name in gone:
            del self._rows[name]
        return changed or bool(gone)

    def diagnostics(self, msg: m.DiagnosticStatus, now_s: float) -> bool:
        """Record a node's diagnostics; True when its level or message changed."""
        row = self._row(msg.node, now_s)
        message = clip(msg.message, 200)
        changed = (row.level, row.message) != (msg.level, message)
        row.level = msg.level
        row.message = message
        row.diag_s = now_s
        return changed

    def get(self, name: str) -> NodeRow | None:
        return self._rows.get(name)

    def view(self) -> list[dict[str, Any]]:
        return [row.view() for _name, row in sorted(self._rows.items())]


# --- latency -------------------------------------------------------------------------


class Latency:
    """Capture-to-gaze latency (ms) over the last `window` samples."""

    def __init__(self, window: int = 300) -> None:
        self._samples: deque[float] = deque(maxlen=window)
        self.last: float | None = None

    def add(self, ms: float) -> None:
        self.last = ms
        self._samples.append(ms)

    def percentile(self, q: float) -> float | None:
        """Nearest-rank percentile (q in 0..100); None without samples."""
        if not self._samples:
            return None
        ordered = sorted(self._samples)
        rank = max(1, math.ceil(q / 100.0 * len(ordered)))
        return ordered[rank - 1]

    def view(self) -> dict[str, Any]:
        return {"last_ms": self.last, "p50_ms": self.percentile(50),
                "p95_ms": self.percentile(95), "n": len(self._samples)}


# --- one page's queue ----------------------------------------------------------------


class Outbox:
    """What one page has not been sent yet: the newest value per slot, except
    radar frames, which are appended (bounded) so its plot has no holes.

    Its size is bounded by the number of slots whatever the message rate,
    so a page that reads slowly costs the server a fixed amount of memory.
    """

    def __init__(self) -> None:
        self._slots: dict[str, Any] = {}
        self._frames: list[dict[str, Any]] = []
        self.dropped_frames = 0

    def put(self, slot: str, value: Any) -> None:
        self._slots.pop(slot, None)
        self._slots[slot] = value  # re-inserted last: arrival order is kept

    def put_frames(self, frames: list[dict[str, Any]]) -> None:
        self._frames.extend(frames)
        extra = len(self._frames) - MAX_QUEUED_FRAMES
        if extra > 0:
            del self._frames[:extra]
            self.dropped_frames += extra

    def take(self) -> list[tuple[str, Any]]:
        out = list(self._slots.items())
        self._slots.clear()
        if self._frames:
            out.append(("radar", self._frames))
            self._frames = []
        return out

    def __bool__(self) -> bool:
        return bool(self._slots or self._frames)


# --- requests from a page ------------------------------------------------------------

MAX_LOOK_YAW = 1.0
"""Radians a gaze button may ask for (57 degrees: past the eye page's 40 degree edge)."""
MAX_LOOK_PITCH = 0.8

class SetExpression(msgspec.Struct, tag="expression", tag_field="op", forbid_unknown_fields=True):
    action: Annotated[str, msgspec.Meta(max_length=64)]
    """An `ExpressionAction` name (`EYE_GRIN`): names, so the page needs no numbers."""
    id: Annotated[int, msgspec.Meta(ge=0, le=2**53)] = 0


class PlaySound(msgspec.Struct, tag="play", tag_field="op", forbid_unknown_fields=True):
    sound: Annotated[str, msgspec.Meta(min_length=1, max_length=256)]
    id: Annotated[int, msgspec.Meta(ge=0, le=2**53)] = 0


class StopSound(msgspec.Struct, tag="stop", tag_field="op", forbid_unknown_fields=True):
    id: Annotated[int, msgspec.Meta(ge=0, le=2**53)] = 0


class Control(msgspec.Struct, tag="control", tag_field="op", forbid_unknown_fields=True):
    """The operator switch: on takes the dashboard's operator lease, off gives it back."""
    on: bool
    id: Annotated[int, msgspec.Meta(ge=0, le=2**53)] = 0


class Look(msgspec.Struct, tag="gaze", tag_field="op", forbid_unknown_fields=True):
    """Where the eyes look (radians, + = the robot's left / up), under the lease."""
    yaw: Annotated[float, msgspec.Meta(ge=-MAX_LOOK_YAW, le=MAX_LOOK_YAW)]
    pitch: Annotated[float, msgspec.Meta(ge=-MAX_LOOK_PITCH, le=MAX_LOOK_PITCH)]
    id: Annotated[int, msgspec.Meta(ge=0, le=2**53)] = 0


class BreakLease(msgspec.Struct, tag="break", tag_field="op", forbid_unknown_fields=True):
    """End anyone's lease (`leases/release`, reason "broken by operator")."""
    lease_id: Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
    id: Annotated[int, msgspec.Meta(ge=0, le=2**53)] = 0


Command = (SetExpression | PlaySound | StopSound | Control | Look | BreakLease
           | identity.EnrolFace | identity.ForgetFace | identity.ListKnown)
_command_decoder: msgspec.json.Decoder[Command] = msgspec.json.Decoder(Command)
MAX_COMMAND_BYTES = 4096


class BadCommand(ValueError):
    """A page sent something that is not a command: its text goes back to the page."""


def parse_command(text: str | bytes) -> Command:
    """A page's request, validated; BadCommand with a one-line reason otherwise."""
    if len(text) > MAX_COMMAND_BYTES:
        raise BadCommand(f"request too large: {len(text)} bytes (limit {MAX_COMMAND_BYTES})")
    try:
        cmd = _command_decoder.decode(text)
    except (msgspec.DecodeError, msgspec.ValidationError) as exc:
        raise BadCommand(f"bad request: {clip(exc, 200)} (expected e.g. "
                         '{"op": "expression", "action": "EYE_GRIN"}, '
                         '{"op": "play", "sound": "greeting"}, {"op": "stop"}, '
                         '{"op": "control", "on": true}, {"op": "gaze", "yaw": 0.3, "pitch": 0}'
                         ', {"op": "break", "lease_id": "..."}, {"op": "enrol", "name": "Ada"}, '
                         '{"op": "forget", "name": "Ada"} or {"op": "known"})') from None
    if isinstance(cmd, SetExpression) and cmd.action not in m.ExpressionAction.__members__:
        raise BadCommand(f"unknown expression {clip(cmd.action, 64)!r}: one of "
                         f"{', '.join(m.ExpressionAction.__members__)}")
    return cmd


# --- small rules ---------------------------------------------------------------------

PRESENCE_FIELDS = ("range_m", "exit_margin_m", "absence_hold_s", "target_hold_s")


def presence_rules(reply: m.ParamReply) -> dict[str, float] | None:
    """range and holds from radar-presence's `params` reply; None when it has none."""
    if reply.error:
        return None
    found: dict[str, float] = {}
    for p in reply.params:
        if p.name in PRESENCE_FIELDS and isinstance(p.value, (int, float)) \
                and not isinstance(p.value, bool) and math.isfinite(p.value):
            found[p.name] = float(p.value)
    return found if "range_m" in found else None


def sound_names(reply: m.ParamReply | None, configured: dict[str, str]) -> list[str]:
    """The audio service's sound names: from its live `sounds` parameter when it
    answered, else from this machine's config (`[audio] sounds`)."""
    if reply is not None and not reply.error:
        for p in reply.params:
            if p.name == "sounds" and isinstance(p.value, dict):
                return sorted(str(k) for k in p.value)[:64]
    return sorted(configured)[:64]


def eye_page_url(configured: str, eye_port: int, page_host: str | None) -> str:
    """The eye page the dashboard shows: the configured URL, else the eye renderer
    at `eye_port` on the host name the dashboard itself was opened with (so a
    laptop that reached the dashboard reaches the eyes the same way)."""
    if configured:
        return configured
    host = "127.0.0.1"
    if page_host:
        parsed = urlsplit(f"//{page_host}")
        if parsed.hostname:
            host = parsed.hostname
    if ":" in host:  # IPv6 literal
        host = f"[{host}]"
    return f"http://{host}:{eye_port}/eyes?eye=both"


def enum_names() -> dict[str, dict[int, str]]:
    """Number -> name of the enums the page shows (sent once in its hello)."""
    kinds: list[type[Any]] = [m.ExpressionAction, m.TargetState, m.PresenceState,
                              m.PresenceTarget, m.EyeId]
    return {k.__name__: {int(v): v.name for v in k} for k in kinds}


# --- leases --------------------------------------------------------------------------


def leases_view(state: m.Leases | None, own: str | None) -> dict[str, Any]:
    """The lease panel: every lease now (the dashboard's own marked), the ended
    ones newest first, and whether the operator holds control (`own`: the
    dashboard's lease id, kept until a newer `leases/state` no longer lists
    it). `state` None: the controller has not published `leases/state`."""
    if state is None:
        return {"known": False, "holding": own is not None, "own": own, "leases": [],
                "ended": []}
    leases = [{
        "lease_id": lease.lease_id, "holder": lease.holder, "priority": lease.priority,
        "resources": list(lease.resources), "since": lease.granted_ns / 1e9,
        "expires": None if lease.expires_ns is None else lease.expires_ns / 1e9,
        "own": own is not None and lease.lease_id == own,
    } for lease in state.leases]
    ended = [{
        "lease_id": end.lease_id, "holder": end.holder, "reason": end.reason,
        "message": clip(end.message, 200), "t": end.stamp_ns / 1e9,
    } for end in reversed(state.ended)]
    return {"known": True, "holding": own is not None, "own": own,
            "leases": leases, "ended": ended}
