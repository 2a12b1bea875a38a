"""Recordings for ROS 2 tools: our messages <-> rosbag2 MCAP channels (pure, no Zenoh).

`bag export --ros2` and `bag import` stand on it; our own recordings are
`tools/bag.py`'s (the CLI joins the two, as the layers say).

* `TABLE`: which of our topics becomes which ROS 2 topic, the original
  robot's names (`/face_position`, ...), and the types `bag import` takes
  on it; `people/state` becomes the ROS4HRI topics (hri.py), other keys
  without an entry are skipped. What is written is what the bridge
  publishes (`bridge.outgoing` of the same `[ros2]` settings): each
  topic's type, CDR and offered QoS, so a bag
  replays into the subscribers the live robot serves (`/raw_image` an
  Image unless `raw_image = "compressed"`; a test holds every topic's QoS
  equal to the bridge's).
* `message_definition`: the `ros2msg` schema text rosbag2 stores (the
  type's `.msg` text, then every dependency under a line of 80 `=`).
* `Rosbag2Writer`: a rosbag2 directory (`metadata.yaml` version 9 and one
  MCAP file, profile `ros2`, CDR) that `ros2 bag play DIR` and
  `ros2 bag play DIR/DIR_0.mcap` both read.
* `Importer`: one ROS 2 channel at a time, told apart before any message is
  read (a topic we do not map, a type we do not take on it, a schema that
  defines the type otherwise, or not CDR: skipped, with the reason); its
  messages pass `convert`'s checked decoding, a refused one counted.

Details: docs/recording.md, 'Recordings for ROS 2 tools'.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mcap.writer import CompressionType, Writer
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import Typestore

from buddybot import __version__
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, convert, hri, interfaces, types, wire
from buddybot.ros2.settings import Ros2Settings

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_VERSION = 9
"""rosbag2's metadata version of Jazzy (`type_description_hash` per topic)."""
ROS_DISTRO = "jazzy"
STORAGE = "mcap"
CHUNK_BYTES = 768 * 1024
"""rosbag2's own MCAP chunk size."""
MAX_SCHEMA_BYTES = 64 * 1024
"""Largest schema text parsed on import (the largest of ours is under 4 kB)."""
SEPARATOR = "=" * 80


class Ros2BagError(ValueError):
    """A ROS 2 recording that cannot be written or taken in; the text says why."""


# --- the table ------------------------------------------------------------------


@dataclass(frozen=True)
class BagTopic:
    """Our topic `topic` as the ROS 2 topic `/name`; `bag import` takes it as
    one of `ros_types`, unless `not_taken` says why it cannot be read back.
    The type written is the bridge's."""

    topic: keys.Topic
    name: str
    ros_types: tuple[str, ...]
    not_taken: str = ""

    @property
    def ros_name(self) -> str:
        return f"/{self.name}"


def _ours(cls: type[m.Message]) -> tuple[str, ...]:
    return (convert.OURS[cls],)


_IMAGES = (types.COMPRESSED_IMAGE, types.IMAGE)
TABLE: tuple[BagTopic, ...] = (
    BagTopic(keys.FACE, "face_position", (types.POINT_STAMPED,)),
    BagTopic(keys.CAMERA_IMAGE, "raw_image", _IMAGES),
    BagTopic(keys.DEBUG_IMAGE, "debug_image", _IMAGES),
    BagTopic(keys.RADAR_FRAMES, "ld2410_target_frames", _ours(m.LD2410TargetDataFrameArray)),
    BagTopic(keys.RADAR_TARGETS, "ld2450_targets", (types.POSE_ARRAY,),
             "written only: a PoseArray lacks the targets' slot, speed and resolution"),
    BagTopic(keys.PRESENCE, "radar_presence", _ours(m.PresenceDetection)),
    BagTopic(keys.EXPRESSION, "screen_expression", _ours(m.ScreenExpression)),
    BagTopic(keys.EYE_CONTROL, "eye_control", _ours(m.EyeControl)),
    BagTopic(keys.EYES_DIRECTION, "eyes_direction_control", _ours(m.EyesDirection)),
    BagTopic(keys.PUPIL, "pupil_control", _ours(m.PupilControl)),
    BagTopic(keys.LIDS, "eye_lid_control", _ours(m.EyeLidControl)),
    BagTopic(keys.DEVICE_FREE, "audio_device_is_free", (types.BOOL,)),
)
BY_TOPIC: dict[keys.Topic, BagTopic] = {t.topic: t for t in TABLE}
BY_NAME: dict[str, BagTopic] = {t.ros_name: t for t in TABLE}


def live(settings: Ros2Settings) -> dict[str, bridge.Outgoing]:
    """The bridge's publishers under `settings`, by ROS 2 name (relative)."""
    return {out.name: out for out in bridge.outgoing(settings)}


def to_ros(entry: BagTopic, message: m.Message, settings: Ros2Settings | None = None
           ) -> tuple[str, bytes]:
    """(ROS type, CDR payload) of one of our messages on `entry`'s topic, as
    the bridge under `settings` (default: `[ros2]`'s defaults) publishes it."""
    out = live(settings or Ros2Settings())[entry.name]
    return out.ros_type, out.encode(message)


def from_ros(entry: BagTopic, ros_type: str, payload: bytes | memoryview,
             log_time_ns: int) -> m.Message:
    """Our message from a ROS 2 payload of `entry`'s topic, checked
    (`convert.ConvertError` says why not). A Bool has no stamp: the log time."""
    if entry.not_taken:
        raise convert.ConvertError(f"{entry.ros_name}: {entry.not_taken}")
    if ros_type not in entry.ros_types:
        raise convert.ConvertError(f"{entry.ros_name}: type {ros_type} is not taken here")
    if ros_type == types.POINT_STAMPED:
        return convert.face_from_ros(payload)
    if ros_type in _IMAGES:
        return convert.image_from_ros(payload, ros_type)
    if ros_type == types.BOOL:
        return convert.bool_from_ros(payload, log_time_ns)
    return convert.from_ros(payload, entry.topic.type)


def relative_key(entry: BagTopic, message: m.Message, camera: str) -> str:
    """Our relative key of an imported message: the radar's from its
    `device_id`, a camera's the one given (ROS 2 names carry no camera)."""
    params: dict[str, str] = {}
    if "camera" in entry.topic.params:
        params["camera"] = camera
    if "device" in entry.topic.params:
        params["device"] = str(getattr(message, "device_id", 0))
    return entry.topic.key(**params)


# --- message definitions -----------------------------------------------------------


def _dependencies(store: Typestore, name: str) -> list[str]:
    """Every type `name` refers to, depth first, each once, in rosbag2's order."""
    found: list[str] = []

    def refs(desc: Any) -> list[str]:
        kind, spec = desc
        if kind == 2:  # NAME
            return [spec]
        if kind in (3, 4):  # ARRAY, SEQUENCE
            return refs(spec[0])
        return []

    def visit(typename: str) -> None:
        for _fname, desc in store.fielddefs[typename][1]:
            for ref in refs(desc):
                if ref not in found:
                    found.append(ref)
                    visit(ref)

    visit(name)
    return found


def _own_text(name: str) -> str:
    """The `.msg` text of one type: ours as generated, a standard one rebuilt."""
    pkg, _, base = name.split("/")
    if pkg == types.OURS:
        return interfaces.generate()[f"msg/{base}.msg"]
    text, _ = types.typestore().gendefhash(name, {}, 2)
    return str(text)


def message_definition(name: str) -> str:
    """The complete `ros2msg` definition of message `name` as rosbag2 stores it."""
    store = types.typestore()
    if name not in store.fielddefs:
        raise KeyError(f"unknown ROS 2 type {name!r}")
    parts = [_own_text(name).rstrip("\n") + "\n"]
    for dep in _dependencies(store, name):
        parts.append(f"{SEPARATOR}\nMSG: {dep}\n{_own_text(dep).rstrip(chr(10))}\n")
    return "".join(parts)


def _sections(text: str, name: str) -> dict[str, str]:
    """Type name -> its own text, from a complete definition."""
    found = {name: ""}
    current = name
    lines: list[str] = []
    chunks = text.split("\n")
    i = 0
    while i < len(chunks):
        line = chunks[i]
        if line.strip() == SEPARATOR and i + 1 < len(chunks) \
                and chunks[i + 1].startswith("MSG: "):
            found[current] = "\n".join(lines)
            current = _normal(chunks[i + 1][5:].strip())
            lines = []
            i += 2
            continue
        lines.append(line)
        i += 1
    found[current] = "\n".join(lines)
    return found


def _normal(name: str) -> str:
    """`pkg/Name` (ROS 1 style, some writers) -> `pkg/msg/Name`."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


def _plain(desc: Any) -> Any:
    """A field description with `char` as `uint8` (rosidl's reading, and ours)."""
    return types._char_as_uint8(desc)


def check_definition(text: str, name: str) -> str:
    """'' when the `ros2msg` text defines `name` and its dependencies field
    for field as our store does, else what differs (the first difference)."""
    if len(text.encode()) > MAX_SCHEMA_BYTES:
        return f"a schema of {len(text.encode())} bytes (limit {MAX_SCHEMA_BYTES})"
    parsed: dict[str, Any] = {}
    try:
        for section, body in _sections(text, name).items():
            parsed.update(get_types_from_msg(body, section))
    except Exception as exc:  # rosbags' parser raises its own and ValueError
        return f"a schema that does not parse ({type(exc).__name__}: {str(exc)[:120]})"
    store = types.typestore()
    for typename in [name, *_dependencies(store, name)]:
        ours = [(f, _plain(d)) for f, d in store.fielddefs[typename][1]]
        theirs = parsed.get(typename)
        if theirs is None:
            return f"a schema without the definition of {typename}"
        got = [(f, _plain(d)) for f, d in theirs[1]]
        if got != ours:
            return (f"a schema that defines {typename} otherwise "
                    f"(fields {[f for f, _ in got][:12]}, ours {[f for f, _ in ours][:12]})"
                    if [f for f, _ in got] != [f for f, _ in ours]
                    else f"a schema that gives {typename} other field types than ours")
    return ""


# --- QoS and metadata -----------------------------------------------------------------

_INFINITE = {"sec": 9223372036, "nsec": 854775807}
"""RMW_DURATION_INFINITE as rosbag2 (Iron and later) writes it."""


_RELIABILITY = {None: "reliable", wire.RELIABLE: "reliable", wire.BEST_EFFORT: "best_effort"}
_DURABILITY = {None: "volatile", wire.VOLATILE: "volatile",
               wire.TRANSIENT_LOCAL: "transient_local"}
_HISTORY = {None: "keep_last", 1: "keep_last", 2: "keep_all"}


def qos_profile(qos: wire.Qos) -> dict[str, Any]:
    """rosbag2's offered QoS profile of a publisher that announces `qos` in its
    graph token (an empty component is rmw's default: reliable, volatile,
    keep last, no deadline, lifespan or lease). `ros2 bag play` offers it
    again, so a replay matches the subscribers the live topic matched."""
    unset = (qos.deadline_sec, qos.deadline_nsec, qos.lifespan_sec, qos.lifespan_nsec,
             qos.liveliness, qos.liveliness_lease_sec, qos.liveliness_lease_nsec)
    if any(x is not None for x in unset):
        raise ValueError(f"QoS {qos.format()}: deadline, lifespan and liveliness are "
                         "not written to a bag")
    return {
        "history": _HISTORY[qos.history], "depth": 10 if qos.depth is None else qos.depth,
        "reliability": _RELIABILITY[qos.reliability], "durability": _DURABILITY[qos.durability],
        "deadline": dict(_INFINITE), "lifespan": dict(_INFINITE), "liveliness": "automatic",
        "liveliness_lease_duration": dict(_INFINITE), "avoid_ros_namespace_conventions": False,
    }


def _yaml(value: Any, indent: int = 0) -> list[str]:
    """Block YAML of plain dicts, lists, strings, ints and bools (JSON-quoted
    strings are YAML double-quoted scalars)."""
    pad = " " * indent
    lines: list[str] = []
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, dict | list) and item:
                lines.append(f"{pad}{key}:")
                lines.extend(_yaml(item, indent + 2))
            else:
                lines.append(f"{pad}{key}: {_scalar(item)}")
    elif isinstance(value, list):
        for item in value:
            inner = _yaml(item, indent + 2)
            lines.append(f"{pad}- {inner[0].lstrip()}")
            lines.extend(inner[1:])
    else:
        lines.append(f"{pad}{_scalar(value)}")
    return lines


def _scalar(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if value is None or value == {} or value == []:
        return "~" if value is None else ("{}" if value == {} else "[]")
    return json.dumps(str(value))


def yaml_text(value: Any) -> str:
    return "\n".join(_yaml(value)) + "\n"


# --- writing ------------------------------------------------------------------------


@dataclass
class _Channel:
    id: int
    ros_name: str
    ros_type: str
    qos: dict[str, Any]
    count: int = 0


@dataclass
class ExportStats:
    """What an export wrote and what it left out."""

    messages: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    """Our key -> why it is not in the ROS 2 recording."""
    refused: int = 0


class Rosbag2Writer:
    """Writes a rosbag2 directory: `DIR/metadata.yaml` and `DIR/DIR_0.mcap`.

    `DIR` must not exist or be empty (as `ros2 bag record` refuses to
    overwrite). Each topic is written as the bridge under `settings`
    publishes it (type, CDR, QoS). Not thread-safe; `close()` writes the
    summary and the metadata, without which `ros2 bag play` refuses the
    directory."""

    def __init__(self, directory: str | Path, settings: Ros2Settings | None = None) -> None:
        self.directory = Path(directory)
        self.settings = settings or Ros2Settings()
        self._live = live(self.settings)
        self._hri = hri.HriPlanner(self.settings.robot_frame)
        """The people as ROS4HRI, sent on change as the bridge does."""
        self._made = not self.directory.exists()
        if self.directory.exists() and (not self.directory.is_dir()
                                        or any(self.directory.iterdir())):
            raise Ros2BagError(f"{directory}: exists and is not an empty directory")
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            self.file = self.directory / f"{self.directory.resolve().name}_0.mcap"
            self._stream: IO[bytes] = open(self.file, "wb")  # noqa: SIM115 (closed in close())
        except OSError as exc:
            raise Ros2BagError(f"{directory}: cannot write: {exc.strerror or exc}") from None
        self._writer = Writer(self._stream, chunk_size=CHUNK_BYTES,
                              compression=CompressionType.ZSTD, enable_data_crcs=True)
        self._writer.start(profile=PROFILE, library=f"buddybot {__version__}")
        self._schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], _Channel] = {}
        self.stats = ExportStats()
        self.start_ns: int | None = None
        self.end_ns = 0
        self._closed = False

    def _schema(self, ros_type: str) -> int:
        found = self._schemas.get(ros_type)
        if found is None:
            found = self._schemas[ros_type] = self._writer.register_schema(
                ros_type, SCHEMA_ENCODING, message_definition(ros_type).encode())
        return found

    def _channel(self, ros_name: str, ros_type: str, offered: wire.Qos) -> _Channel:
        found = self._channels.get((ros_name, ros_type))
        if found is None:
            qos = qos_profile(offered)
            cid = self._writer.register_channel(
                ros_name, MESSAGE_ENCODING, self._schema(ros_type),
                {"offered_qos_profiles": yaml_text([qos]).rstrip("\n"),
                 "topic_type_hash": types.type_hash(ros_type)})
            found = self._channels[(ros_name, ros_type)] = _Channel(cid, ros_name, ros_type,
                                                                    qos)
        return found

    def _add(self, channel: _Channel, payload: bytes, stamp_ns: int | None,
             log_time_ns: int) -> None:
        self._writer.add_message(channel.id, log_time=log_time_ns, data=payload,
                                 publish_time=int(stamp_ns) if stamp_ns else log_time_ns,
                                 sequence=channel.count)
        channel.count += 1
        self.stats.messages += 1
        name = channel.ros_name
        self.stats.per_topic[name] = self.stats.per_topic.get(name, 0) + 1
        self.start_ns = log_time_ns if self.start_ns is None else min(self.start_ns,
                                                                       log_time_ns)
        self.end_ns = max(self.end_ns, log_time_ns)

    def _people(self, state: m.PeopleState, log_time_ns: int) -> bool:
        """`people/state` as the bridge publishes it: the ROS4HRI topics (hri.py)."""
        for sample in self._hri.step(state).samples:
            channel = self._channel(f"/{sample.name}", sample.ros_type, hri.qos(sample.name))
            self._add(channel, sample.payload, state.stamp_ns, log_time_ns)
        return True

    def write(self, key: str, topic: keys.Topic, message: m.Message, log_time_ns: int) -> bool:
        """Write one of our messages (recorded on `key` at `log_time_ns`) on its
        ROS 2 topic; False when its topic has none (noted in `stats.skipped`)."""
        if topic is keys.PEOPLE_STATE and isinstance(message, m.PeopleState):
            return self._people(message, log_time_ns)
        entry = BY_TOPIC.get(topic)
        out = None if entry is None else self._live.get(entry.name)
        if entry is None or out is None:
            self.stats.skipped.setdefault(key, "no ROS 2 topic" if entry is None
                                          else "the bridge does not publish it")
            return False
        try:
            payload = out.encode(message)
        except (convert.ConvertError, ValueError, OverflowError) as exc:
            self.stats.refused += 1
            self.stats.skipped.setdefault(key, f"not convertible: {str(exc)[:120]}")
            return False
        channel = self._channel(entry.ros_name, out.ros_type, out.qos)
        self._add(channel, payload, getattr(message, "stamp_ns", None), log_time_ns)
        return True

    def metadata(self) -> dict[str, Any]:
        """rosbag2's `metadata.yaml` content (version 9)."""
        start = self.start_ns or 0
        duration = max(0, self.end_ns - start)
        topics = [{
            "topic_metadata": {
                "name": c.ros_name, "type": c.ros_type,
                "serialization_format": MESSAGE_ENCODING,
                "offered_qos_profiles": [c.qos],
                "type_description_hash": types.type_hash(c.ros_type),
            },
            "message_count": c.count,
        } for c in self._channels.values()]
        return {"rosbag2_bagfile_information": {
            "version": METADATA_VERSION, "storage_identifier": STORAGE,
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self.stats.messages,
            "topics_with_message_count": topics,
            "compression_format": "", "compression_mode": "",
            "relative_file_paths": [self.file.name],
            "files": [{"path": self.file.name,
                       "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration},
                       "message_count": self.stats.messages}],
            "custom_data": {"buddybot_version": __version__},
            "ros_distro": ROS_DISTRO,
        }}

    def close(self) -> None:
        """Finish the MCAP file (its `rosbag2` metadata record included) and
        write `metadata.yaml` next to it (safe twice)."""
        if self._closed:
            return
        self._closed = True
        meta = self.metadata()
        text = yaml_text(meta)
        try:
            self._writer.add_metadata("rosbag2", {
                "serialized_metadata": yaml_text(meta["rosbag2_bagfile_information"]),
                "ROS_DISTRO": ROS_DISTRO})
            self._writer.finish()
        finally:
            self._stream.close()
        (self.directory / "metadata.yaml").write_text(text)

    def abort(self) -> None:
        """Close and remove what was written (a failed export leaves nothing
        that looks like a finished bag)."""
        if not self._closed:
            self._closed = True
            self._stream.close()
        self.file.unlink(missing_ok=True)
        (self.directory / "metadata.yaml").unlink(missing_ok=True)
        if self._made:
            self.directory.rmdir()


# --- reading --------------------------------------------------------------------------


@dataclass
class ImportStats:
    """What an import took, skipped and refused."""

    messages: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    """ROS 2 topic -> why its channel is not taken."""
    malformed: dict[str, int] = field(default_factory=dict)
    """ROS 2 topic -> messages refused (bad CDR, values outside the contract)."""
    first_error: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Accepted:
    """A ROS 2 channel taken in: its table entry and type."""

    entry: BagTopic
    ros_type: str


def accept_channel(topic: str, schema_name: str, schema_encoding: str, schema_text: bytes,
                   message_encoding: str) -> Accepted | str:
    """The channel's entry when we take it, else why not (pure, before any
    message is read)."""
    entry = BY_NAME.get(topic)
    if entry is None:
        return "no BuddyBot key for this topic"
    if entry.not_taken:
        return entry.not_taken
    if message_encoding != MESSAGE_ENCODING:
        return f"message encoding {message_encoding[:32]!r} (only cdr)"
    if schema_name not in entry.ros_types:
        return f"type {schema_name[:120]} (taken here: {', '.join(entry.ros_types)})"
    if schema_encoding != SCHEMA_ENCODING:
        return f"schema encoding {schema_encoding[:32]!r} (only ros2msg)"
    try:
        text = schema_text.decode()
    except UnicodeDecodeError:
        return "a schema that is not UTF-8 text"
    problem = check_definition(text, schema_name)
    return problem or Accepted(entry, schema_name)


def mcap_files(path: str | Path) -> list[Path]:
    """The MCAP files of a recording: the file itself, or a rosbag2
    directory's `*.mcap` files in their split order (`x_0`, `x_1`, ...)."""
    path = Path(path)
    if not path.is_dir():
        return [path]
    files = [p for p in path.iterdir() if p.suffix == ".mcap" and p.is_file()]
    if not files:
        raise Ros2BagError(f"{path}: a directory without .mcap files")

    def order(p: Path) -> tuple[int, str]:
        found = re.search(r"_(\d+)$", p.stem)
        return (int(found.group(1)) if found else -1, p.name)

    return sorted(files, key=order)

