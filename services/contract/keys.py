"""The key catalogue: every key expression (docs/design.md section 2), once.

Each entry binds a key pattern (relative to `buddybot/<robot>/`) to its
message type, wire codec, QoS preset and whether it is latched. The node
runtime, the CLI, the schema generator and the tests all read this
table, so a key string is typed exactly here and nowhere else.

This module is pure: QoS is described as data and translated to Zenoh
settings by `node.py`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import cache
from typing import Any, Literal

import msgspec

from buddybot.contract import messages as m

PREFIX_ROOT = "buddybot"
DEFAULT_ROBOT = "buddy"
ID_MAX = 64
"""The longest robot id or name (node, camera, device) a key chunk may carry: ids
come from files, flags and the network, and every key, log line and table
holds them."""
_ROBOT_ID = re.compile(rf"[A-Za-z0-9_-]{{1,{ID_MAX}}}")
_PARAM = re.compile(r"\{(\w+)\}")


def valid_robot_id(robot: str) -> bool:
    """A robot id (or a node's, camera's name) is one key chunk of 1-ID_MAX
    letters, digits, '-' or '_': no wildcards, separators or line breaks."""
    return bool(_ROBOT_ID.fullmatch(robot))


def prefix(robot: str) -> str:
    """`buddybot/<robot>`: the root of every key of one robot."""
    if not valid_robot_id(robot):
        raise ValueError(f"invalid robot id {robot[:ID_MAX]!r}: use 1-{ID_MAX} letters, "
                         "digits, '-' or '_'")
    return f"{PREFIX_ROOT}/{robot}"


def absolute(robot: str, key: str) -> str:
    """Prefix a relative key; a key already starting with `buddybot/` is kept."""
    key = key.strip("/")
    if key == PREFIX_ROOT or key.startswith(PREFIX_ROOT + "/"):
        return key
    return f"{prefix(robot)}/{key}"


def split_absolute(key: str) -> tuple[str, str] | None:
    """`buddybot/<robot>/<rest>` -> (robot, rest); None for a foreign key."""
    parts = str(key).split("/", 2)
    if len(parts) < 3 or parts[0] != PREFIX_ROOT:
        return None
    return parts[1], parts[2]


def relative(robot: str, key: str) -> str:
    """A key of `robot` without its `buddybot/<robot>/` prefix; any other key
    (another robot's, a foreign one, one already relative) unchanged."""
    parts = split_absolute(key)
    return parts[1] if parts is not None and parts[0] == robot else str(key)


# --- codecs ------------------------------------------------------------------


@dataclass(frozen=True)
class Codec:
    """How a message type is put on the wire, and the Zenoh encoding naming it."""

    name: Literal["json", "msgpack"]
    mime: str

    def encoding(self, msg_type: type) -> str:
        """Zenoh encoding string, e.g. `application/json;buddybot/EyeControl`."""
        return f"{self.mime};{PREFIX_ROOT}/{msg_type.__name__}"

    def encode(self, msg: Any) -> bytes:
        return _encoder(self.name).encode(msg)

    def decode(self, data: bytes | bytearray | memoryview, msg_type: type[Any]) -> Any:
        """Decode and validate; raises msgspec.DecodeError/ValidationError."""
        kind: Any = msg_type  # a struct class: hashable, the decoder cache's key
        return _decoder(self.name, kind).decode(data)


@cache
def _encoder(name: str) -> msgspec.json.Encoder | msgspec.msgpack.Encoder:
    return msgspec.json.Encoder() if name == "json" else msgspec.msgpack.Encoder()


@cache
def _decoder(
    name: str, msg_type: Any
) -> msgspec.json.Decoder[Any] | msgspec.msgpack.Decoder[Any]:
    if name == "json":
        return msgspec.json.Decoder(msg_type)
    return msgspec.msgpack.Decoder(msg_type)


JSON = Codec("json", "application/json")
MSGPACK = Codec("msgpack", "application/msgpack")


def codec_for_encoding(encoding: str) -> Codec | None:
    """The codec named by a sample's encoding string, if it is one of ours."""
    mime = str(encoding).split(";", 1)[0]
    for codec in (JSON, MSGPACK):
        if codec.mime == mime:
            return codec
    return None


# --- QoS presets -------------------------------------------------------------


@dataclass(frozen=True)
class QoS:
    """Delivery policy as data.

    Every preset uses congestion control DROP: with BLOCK, one stalled
    reader makes the router hold back every other stream (radar frames
    stop for seconds; tests/system/test_stall.py). What must not be lost (state) is latched
    instead: the advanced publisher keeps its last samples and the
    subscribers detect a missed sample (heartbeat) and fetch it again, so
    "state" means "always converges to the newest value", not "blocks".
    """

    congestion: Literal["drop"]
    priority: Literal["real_time", "interactive_high", "data", "background"]
    express: bool = False


STREAM = QoS("drop", "data")
"""Sensor streams: every sample matters little once a newer one exists."""
IMAGES = QoS("drop", "data")
"""Camera images: large, dropped under congestion."""
STATE = QoS("drop", "interactive_high", express=True)
"""State changes: small, sent at once, latched so a dropped one is recovered."""
BACKGROUND = QoS("drop", "background")
"""Diagnostics and debug output."""

SMALL_MESSAGE_BYTES = 64 * 1024
"""Largest payload accepted on a non-image key (real ones are under 2 kB)."""
IMAGE_MESSAGE_BYTES = 16 * 1024 * 1024
"""Largest image payload accepted (a 1920x1080 bgr8 frame is 6.2 MB); the
router's `max_message_size` is set to the same bound."""


# --- catalogue entries -------------------------------------------------------


@dataclass(frozen=True)
class _Entry:
    pattern: str
    doc: str

    @property
    def params(self) -> tuple[str, ...]:
        return tuple(_PARAM.findall(self.pattern))

    def key(self, **params: str) -> str:
        """The relative key with its `{params}` filled in."""
        missing = set(self.params) - params.keys()
        if missing:
            raise ValueError(f"{self.pattern}: missing {sorted(missing)}")
        for name, value in params.items():
            if not valid_robot_id(str(value)):
                raise ValueError(f"{self.pattern}: invalid {name} {value!r}")
        return self.pattern.format(**params)

    def wildcard(self) -> str:
        """The pattern with every parameter as `*` (to subscribe to all)."""
        return _PARAM.sub("*", self.pattern)

    def match(self, relative_key: str) -> dict[str, str] | None:
        """Parameters if `relative_key` is an instance of this pattern."""
        found = _pattern_regex(self.pattern).fullmatch(relative_key)
        return None if found is None else found.groupdict()


@cache
def _pattern_regex(pattern: str) -> re.Pattern[str]:
    parts = _PARAM.split(pattern)
    out = []
    for i, part in enumerate(parts):
        out.append(f"(?P<{part}>[^/]+)" if i % 2 else re.escape(part))
    return re.compile("".join(out))


@dataclass(frozen=True)
class Topic(_Entry):
    """A published key: message type, codec, QoS, latched or not."""

    type: type[m.Message] = m.Message
    codec: Codec = JSON
    qos: QoS = STATE
    latched: bool = False
    history: int = 1
    """Samples a latched topic's publisher keeps for late joiners and recovery."""
    max_bytes: int = SMALL_MESSAGE_BYTES
    """Larger samples are dropped unread (counted as `oversized`)."""

    @property
    def encoding(self) -> str:
        return self.codec.encoding(self.type)


@dataclass(frozen=True)
class Service(_Entry):
    """A queryable key: request type -> reply type (JSON both ways)."""

    request: type[m.Message] = m.Trigger
    reply: type[m.Message] = m.TriggerReply
    codec: Codec = field(default=JSON)
    max_bytes: int = SMALL_MESSAGE_BYTES
    """Larger requests get an error reply unread."""


RADAR_FRAMES = Topic(
    "radar/{device}/frames", "every LD2410 report frame of one radar bridge",
    type=m.LD2410TargetDataFrameArray, qos=STREAM,
)
RADAR_TARGETS = Topic(
    "radar/{device}/targets",
    "every angle-radar (LD2450) report: targets with position and bearing",
    type=m.RadarTargets, qos=STREAM,
)
PRESENCE = Topic(
    "radar/presence", "someone in range or not, on change",
    type=m.PresenceDetection, qos=STATE, latched=True,
)
CAMERA_IMAGE = Topic(
    "camera/{camera}/image", "camera frames with capture time",
    type=m.Image, codec=MSGPACK, qos=IMAGES, max_bytes=IMAGE_MESSAGE_BYTES,
)
FACE = Topic(
    "camera/{camera}/face", "tracked face centre, metres, ROS axes",
    type=m.FacePosition, qos=STREAM,
)
FACES = Topic(
    "camera/{camera}/faces", "every face of each processed frame, image pixels, for viewers",
    type=m.FaceDetections, qos=STREAM,
)
DEBUG_IMAGE = Topic(
    "camera/{camera}/debug_image", "JPEG with detections drawn, only while watched",
    type=m.Image, codec=MSGPACK, qos=IMAGES, max_bytes=IMAGE_MESSAGE_BYTES,
)
EXPRESSION = Topic(
    "eyes/expression", "the eyes' expression (the arbiter's winner)",
    type=m.ScreenExpression, qos=STATE, latched=True,
)
EYE_CONTROL = Topic(
    "eyes/control", "gaze target, radians and cm", type=m.EyeControl, qos=STREAM,
)
EYES_DIRECTION = Topic(
    "eyes/direction", "gaze for the renderer, degrees", type=m.EyesDirection, qos=STREAM,
)
PUPIL = Topic(
    "eyes/pupil", "pupil dilation percentage", type=m.PupilControl, qos=STREAM,
)
LIDS = Topic(
    "eyes/lids", "lid positions per eye", type=m.EyeLidControl, qos=STATE, latched=True,
)
BEHAVIOUR_EXPRESSION = Topic(
    "controller/expression", "the built-in behaviour's expression: shown while no lease holds it",
    type=m.ScreenExpression, qos=STATE, latched=True,
)
BEHAVIOUR_GAZE = Topic(
    "controller/eye_control", "the built-in behaviour's gaze: shown while no lease holds it",
    type=m.EyeControl, qos=STREAM,
)
CONTROLLER_STATE = Topic(
    "controller/state", "engagement phase, visit, sounds, why the controller waits; on change",
    type=m.ControllerState, qos=STATE, latched=True,
)
PEOPLE_STATE = Topic(
    "people/state", "persons present: distance, zone, engagement; on change",
    type=m.PeopleState, qos=STATE, latched=True,
)
PEOPLE_EVENTS = Topic(
    "people/events", "every arrival, zone change, engagement change and departure",
    type=m.PersonEvent, qos=STREAM,
)
"""Not latched, so STREAM and not STATE (which is always latched): a late joiner must
not take an old ARRIVED for a new one. An event lost under congestion is not
fetched again; `people/state` (latched) is what converges."""
SIM_WORLD = Topic(
    "sim/world", "the simulated world's truth: every person, where, seen by which sensor",
    type=m.SimWorld, qos=STREAM,
)
"""Only while simulating (`up --sim`); a real robot has no such key."""
FACE_NAME = Topic(
    "identity/{camera}/name", "who the followed face is (per track, after a vote); on change",
    type=m.FaceName, qos=STATE, latched=True,
)
IDENTITY_ENROL = Service(
    "identity/enrol", "remember the one face in front of the camera under a name (consent)",
    request=m.EnrolRequest, reply=m.EnrolReply,
)
IDENTITY_FORGET = Service(
    "identity/forget", "erase one person's face templates, or all of them",
    request=m.ForgetRequest, reply=m.ForgetReply,
)
IDENTITY_LIST = Service(
    "identity/list", "the enrolled people's names and when they were last seen",
    request=m.Trigger, reply=m.KnownPeople,
)
LEASES = Topic(
    "leases/state", "who holds the eyes and the speaker, and the last leases that ended",
    type=m.Leases, qos=STATE, latched=True,
)
LEASE_ACQUIRE = Service(
    "leases/acquire", "take resources (expression, gaze, audio) at a priority",
    request=m.LeaseRequest, reply=m.LeaseReply,
)
LEASE_RELEASE = Service(
    "leases/release", "end a lease: its holder, or an operator breaking it",
    request=m.LeaseRelease, reply=m.TriggerReply,
)
EYES_COMMAND = Service(
    "eyes/command", "a lease holder's expression or gaze, published by the eyes driver",
    request=m.EyesCommand, reply=m.TriggerReply,
)
PLAY_SOUND = Service(
    "audio/play_sound", "action goal: play a named sound",
    request=m.PlaySound, reply=m.PlaySoundReply,
)
PLAY_SOUND_STATUS = Topic(
    "audio/play_sound/status", "action progress and result",
    type=m.PlaySoundStatus, qos=STATE, latched=True, history=16,
)
PLAY_SOUND_CANCEL = Service(
    "audio/play_sound/cancel", "cancel an action goal",
    request=m.CancelGoal, reply=m.TriggerReply,
)
PLAY_FILE = Service(
    "audio/play_file", "player: play a configured sound or a file in its sound folders",
    request=m.PlayAudioFile, reply=m.TriggerReply,
)
AUDIO_STOP = Service("audio/stop", "player: stop playback")
AUDIO_PAUSE = Service("audio/pause", "player: pause playback")
AUDIO_RESUME = Service("audio/resume", "player: resume playback")
DEVICE_FREE = Topic(
    "audio/device_free", "true when the player is idle", type=m.Bool, qos=STATE, latched=True,
)
NODES = _Entry(
    "nodes/{node}/{instance}",
    "liveliness token of each running service; instance = its Zenoh session id (zid)",
)
DIAGNOSTICS = Topic(
    "diagnostics/{node}", "health of each node", type=m.DiagnosticStatus, qos=BACKGROUND,
)
PARAMS = Service(
    "params/{node}", "a node's live settings: list, get, set (set refuses restart-only fields)",
    request=m.ParamRequest, reply=m.ParamReply,
)
NODE_INFO = Service(
    "node_info/{node}", "what a node declared: publishers, subscriptions, services",
    request=m.Trigger, reply=m.NodeInfo,
)

TOPICS: tuple[Topic, ...] = (
    RADAR_FRAMES, RADAR_TARGETS, PRESENCE, CAMERA_IMAGE, FACE, FACES, DEBUG_IMAGE, EXPRESSION,
    EYE_CONTROL, EYES_DIRECTION, PUPIL, LIDS, BEHAVIOUR_EXPRESSION, BEHAVIOUR_GAZE,
    CONTROLLER_STATE, PEOPLE_STATE, PEOPLE_EVENTS,
    FACE_NAME, LEASES, PLAY_SOUND_STATUS, DEVICE_FREE, DIAGNOSTICS, SIM_WORLD,
)
SERVICES: tuple[Service, ...] = (
    IDENTITY_ENROL, IDENTITY_FORGET, IDENTITY_LIST,
    LEASE_ACQUIRE, LEASE_RELEASE, EYES_COMMAND, PLAY_SOUND, PLAY_SOUND_CANCEL, PLAY_FILE,
    AUDIO_STOP, AUDIO_PAUSE, AUDIO_RESUME, PARAMS, NODE_INFO,
)


def lookup(relative_key: str) -> Topic | Service | None:
    """The catalogue entry a concrete relative key belongs to."""
    relative_key = relative_key.strip("/")
    entries: tuple[Topic | Service, ...] = (*TOPICS, *SERVICES)
    for entry in entries:
        if entry.match(relative_key) is not None:
            return entry
    return None


def lookup_absolute(key: str) -> Topic | Service | None:
    """The catalogue entry of an absolute key `buddybot/<robot>/<rest>` (None: a
    foreign key, or one the catalogue does not know)."""
    parts = split_absolute(key)
    return lookup(parts[1]) if parts else None


def key_table() -> list[dict[str, Any]]:
    """The catalogue as plain data (for `schemas/keys.json` and the README)."""
    rows: list[dict[str, Any]] = []
    for t in TOPICS:
        rows.append({
            "key": t.pattern, "kind": "topic", "type": t.type.__name__,
            "encoding": t.encoding, "latched": t.latched,
            "congestion": t.qos.congestion, "priority": t.qos.priority, "doc": t.doc,
        })
    for s in SERVICES:
        rows.append({
            "key": s.pattern, "kind": "service", "request": s.request.__name__,
            "reply": s.reply.__name__, "encoding": s.codec.mime, "doc": s.doc,
        })
    rows.append({"key": NODES.pattern, "kind": "liveliness", "doc": NODES.doc})
    return rows
