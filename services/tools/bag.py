"""Recordings of the robot's keys as MCAP files: naming, writing, checked reading, timing.

`buddybot bag` (record, play, info) stands on this module; it is pure (no
Zenoh), so the file format is tested without a router. The channels come
from `contract/channels.py`, the one place that says how a key looks in MCAP
and in Foxglove:

* one channel per concrete key (`buddybot/buddy/radar/0/frames`), its
  schema and JSON message as `channels.channel()` and `channels.to_json()`
  make them (a JSON key's payload byte for byte; images as
  `foxglove.CompressedImage`);
* `log_time` is the arrival time, `publish_time` the message's `stamp_ns`
  (the arrival time when it has none), so replay keeps the recorded
  timing and the recorded stamps;
* face detections also get a derived `<key>/annotations` channel
  (`foxglove.ImageAnnotations`, marked `derived` in its metadata) so
  Foxglove draws the boxes over the image; replay skips derived channels;
* the robot id and the BuddyBot version are the file's `buddybot` metadata.

A recording is read twice before anything is replayed: its summary (a
file whose recorder was killed has none) and then every record, with
chunk and data-section CRCs checked and every message converted back to
its wire payload, so a damaged file is refused whole instead of played
half-way.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import msgspec
from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel as McapChannel
from mcap.records import Message as McapMessage
from mcap.records import Schema as McapSchema
from mcap.writer import CompressionType, Writer

from buddybot import __version__
from buddybot.contract import channels, keyexpr, keys
from buddybot.runtime import rates
from buddybot.runtime.errors import BuddyBotError
from buddybot.tools import mcap_records

METADATA_NAME = "buddybot"
"""The MCAP metadata record holding the robot id and the recorder's version."""
DERIVED = "derived"
"""Channel metadata key marking a channel computed from another one (not replayed)."""
ANNOTATIONS_SUFFIX = "annotations"
PROFILE = ""
"""MCAP profile: none (the channels are self-describing JSON + jsonschema)."""
CHUNK_BYTES = 1 << 20


class BagError(BuddyBotError):
    """A recording that cannot be read or written (exit status 1); the text
    names the file and what is wrong with it."""


# --- keys ---------------------------------------------------------------------------


def topic_of(key: str) -> keys.Topic | None:
    """The catalogue topic of a concrete absolute key (None: not one of ours)."""
    entry = None if "*" in key else keys.lookup_absolute(key)
    return entry if isinstance(entry, keys.Topic) else None


def annotations_key(faces_key: str) -> str:
    """The derived annotations channel of a `camera/<camera>/faces` key."""
    return f"{faces_key}/{ANNOTATIONS_SUFFIX}"


def with_robot(key: str, robot: str | None) -> str:
    """`key` moved to robot `robot` (`buddybot/<old>/x` -> `buddybot/<robot>/x`)."""
    parts = keys.split_absolute(key)
    if robot is None or parts is None:
        return key
    return f"{keys.prefix(robot)}/{parts[1]}"


def key_matches(expression: str, key: str) -> bool:
    """Whether a concrete key is one of `expression`'s keys, the expression as
    people type it: slashes around it are ignored and a wildcard inside a
    chunk (`cam*`) is Zenoh's `cam$*`."""
    return keyexpr.intersects(_zenoh_form(expression), key.strip("/"))


def _zenoh_form(typed: str) -> str:
    chunks = typed.strip("/").split("/")
    return "/".join(c if c in (keyexpr.STAR, keyexpr.DOUBLE_STAR) or "*" not in c
                    else c.replace(keyexpr.CHUNK_STAR, "*").replace("*", keyexpr.CHUNK_STAR)
                    for c in chunks)


# --- writing ------------------------------------------------------------------------


@dataclass
class WriteStats:
    """What a writer did, for the recorder's progress line and summary."""

    messages: int = 0
    """Messages written (derived annotations not included)."""
    per_key: dict[str, int] = field(default_factory=dict)


class BagWriter:
    """Writes samples of catalogue keys into an MCAP file as their channels.

    Not thread-safe: one thread (the recorder's writer) owns it. `close()`
    writes the summary and index, without which players refuse the file.
    """

    def __init__(self, path: str | Path, *, robot: str, annotations: bool = True,
                 compression: CompressionType = CompressionType.ZSTD) -> None:
        self.path = Path(path)
        try:
            self._stream: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 (closed in close())
        except OSError as exc:
            raise BagError(f"{path}: cannot write: {exc.strerror or exc}") from None
        self._writer = Writer(self._stream, chunk_size=CHUNK_BYTES, compression=compression,
                              enable_data_crcs=True)
        self._writer.start(profile=PROFILE, library=f"buddybot {__version__}")
        self._writer.add_metadata(METADATA_NAME, {"robot": robot, "version": __version__})
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[keys.Topic, int, bool]] = {}
        self._annotation_channels: dict[str, int] = {}
        self._annotations = annotations
        self.stats = WriteStats()
        self._closed = False
        self._final_size = 0

    def _schema_id(self, name: str, data: bytes) -> int:
        found = self._schemas.get(name)
        if found is None:
            found = self._schemas[name] = self._writer.register_schema(
                name, channels.SCHEMA_ENCODING, data)
        return found

    def _channel(self, key: str) -> tuple[keys.Topic, int, bool] | None:
        found = self._channels.get(key)
        if found is None:
            topic = topic_of(key)
            if topic is None:
                return None
            ch = channels.channel(topic)
            channel_id = self._writer.register_channel(
                key, ch.message_encoding, self._schema_id(ch.schema_name, ch.schema),
                {"encoding": topic.encoding})
            found = self._channels[key] = (topic, channel_id, "stamp_ns" in
                                           topic.type.__struct_fields__)
        return found

    def _annotation_channel(self, faces_key: str) -> int:
        found = self._annotation_channels.get(faces_key)
        if found is None:
            schema = self._schema_id(channels.ANNOTATIONS_SCHEMA,
                                     channels.ANNOTATIONS_SCHEMA_BYTES)
            found = self._annotation_channels[faces_key] = self._writer.register_channel(
                annotations_key(faces_key), channels.MESSAGE_ENCODING, schema,
                {DERIVED: faces_key})
        return found

    def write(self, key: str, payload: bytes, arrival_ns: int) -> bool:
        """Write one sample. False: `key` is not a catalogue topic (nothing
        written). Raises channels.ChannelError for a payload its type refuses."""
        found = self._channel(key)
        if found is None:
            return False
        topic, channel_id, stamped = found
        msg = channels.decode(topic, payload)
        data = channels.to_json(topic, payload)
        stamp = int(msg.stamp_ns) if stamped else arrival_ns
        self._writer.add_message(channel_id, log_time=arrival_ns, data=data,
                                 publish_time=stamp, sequence=self.stats.messages)
        self.stats.messages += 1
        self.stats.per_key[key] = self.stats.per_key.get(key, 0) + 1
        if self._annotations and topic is keys.FACES:
            self._writer.add_message(
                self._annotation_channel(key), log_time=arrival_ns, publish_time=stamp,
                data=msgspec.json.encode(channels.annotations(msg)))
        return True

    @property
    def bytes_written(self) -> int:
        """Bytes in the file so far (chunks are flushed as they fill)."""
        if self._closed:
            return self._final_size
        try:
            return self._stream.tell()
        except (OSError, ValueError):
            return 0

    def close(self) -> None:
        """Write the summary, index and footer, and close the file (safe twice)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
            self._final_size = self._stream.tell()
        finally:
            self._stream.close()


# --- reading ------------------------------------------------------------------------


@dataclass(frozen=True)
class ChannelInfo:
    """One channel of a recording, and whether (and why not) it is replayed."""

    id: int
    key: str
    schema: str
    count: int
    topic: keys.Topic | None
    """The catalogue topic replayed on this key (None: not replayed)."""
    skipped: str = ""
    """Why it is not replayed: "" (it is), "derived", or the reason it is unknown."""

    def rate_hz(self, duration_s: float) -> float:
        """Messages per second over the recording (0 for a single message: no rate)."""
        return rates.count_hz(self.count, duration_s) if self.count > 1 else 0.0


@dataclass(frozen=True)
class BagInfo:
    """What a recording's summary says (read without reading its messages)."""

    path: str
    size: int
    start_ns: int
    end_ns: int
    messages: int
    channels: tuple[ChannelInfo, ...]
    metadata: dict[str, str]
    compression: str
    chunk_spans: tuple[tuple[int, int], ...] = ()
    """(offset, length) of every chunk the summary's index points at."""

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) / 1e9

    def as_json(self) -> dict[str, Any]:
        return {
            "path": self.path, "size_bytes": self.size, "duration_s": round(self.duration_s, 6),
            "start_ns": self.start_ns, "end_ns": self.end_ns, "messages": self.messages,
            "compression": self.compression, "metadata": self.metadata,
            "channels": [{"key": c.key, "schema": c.schema, "count": c.count,
                          "rate_hz": round(c.rate_hz(self.duration_s), 3),
                          "replayed": not c.skipped, "skipped": c.skipped}
                         for c in self.channels],
        }


def _classify(channel: McapChannel, schema: McapSchema | None) -> tuple[keys.Topic | None, str]:
    if DERIVED in channel.metadata:
        return None, DERIVED
    topic = topic_of(channel.topic)
    if topic is None:
        return None, "not a topic of the catalogue"
    expected = channels.channel(topic).schema_name
    name = schema.name if schema is not None else ""
    if name != expected or channel.message_encoding != channels.MESSAGE_ENCODING:
        return None, f"schema {name or 'none'} ({channel.message_encoding}), expected {expected}"
    return topic, ""


def _describe(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0][:200]


def read_info(path: str | Path) -> BagInfo:
    """The summary of a recording; BagError when there is none (a truncated
    or unfinished file) or it cannot be parsed."""
    path = Path(path)
    try:
        stream = open(path, "rb")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror or exc}") from None
    with stream:
        size = os.fstat(stream.fileno()).st_size
        _check_magic(path, stream, size)
        if not _summary_crc_ok(stream, size):
            raise BagError(f"{path}: damaged: its summary does not match its CRC; "
                           "refusing to use it")
        stream.seek(0)
        try:
            reader = SeekingReader(stream, record_size_limit=mcap_records.MAX_RECORD_BYTES)
            summary = reader.get_summary()
            metadata: dict[str, str] = {}
            for record in reader.iter_metadata():
                if record.name == METADATA_NAME:
                    metadata = dict(record.metadata)
        except (McapError, Exception) as exc:  # a damaged file raises anything (struct, zstd)
            raise BagError(f"{path}: {_unreadable(path, size, exc)}") from None
    if summary is None or summary.statistics is None:
        raise BagError(f"{path}: no summary: the file is truncated or its recorder was "
                       "killed before finishing it; refusing to use it")
    stats = summary.statistics
    infos = []
    for cid, channel in sorted(summary.channels.items()):
        topic, skipped = _classify(channel, summary.schemas.get(channel.schema_id))
        schema = summary.schemas.get(channel.schema_id)
        infos.append(ChannelInfo(cid, channel.topic, schema.name if schema else "",
                                 stats.channel_message_counts.get(cid, 0), topic, skipped))
    compression = sorted({c.compression or "none" for c in summary.chunk_indexes}) or ["none"]
    return BagInfo(str(path), size, stats.message_start_time, stats.message_end_time,
                   stats.message_count, tuple(infos), metadata, ",".join(compression),
                   tuple((c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes))


_FOOTER_BYTES = 1 + 8 + 8 + 8 + 4
"""The footer record: opcode, length, summary start, summary offset start, summary CRC."""
_MAGIC_BYTES = 8


MAGIC = b"\x89MCAP0\r\n"


def _check_magic(path: Path, stream: IO[bytes], size: int) -> None:
    """The two cheap tells: no MCAP magic at the start (not a recording) or at
    the end (truncated: the recorder was killed, or a copy stopped half-way)."""
    if size == 0:
        raise BagError(f"{path}: empty file")
    if stream.read(_MAGIC_BYTES) != MAGIC:
        raise BagError(f"{path}: not an MCAP file")
    stream.seek(max(0, size - _MAGIC_BYTES))
    if size < 2 * _MAGIC_BYTES + _FOOTER_BYTES or stream.read(_MAGIC_BYTES) != MAGIC:
        raise BagError(f"{path}: truncated: the file has no MCAP footer (its recorder was "
                       "killed, or a copy stopped half-way); refusing to use it")
    stream.seek(0)


def _summary_crc_ok(stream: IO[bytes], size: int) -> bool:
    """Whether the summary section matches the footer's CRC (the MCAP reader
    does not check it, and a flipped byte there could rename a channel)."""
    end = size - _MAGIC_BYTES
    stream.seek(end - _FOOTER_BYTES)
    footer = stream.read(_FOOTER_BYTES)
    summary_start = int.from_bytes(footer[9:17], "little")
    expected = int.from_bytes(footer[25:29], "little")
    if expected == 0 or summary_start == 0:
        return True  # written without a CRC (or without a summary: refused elsewhere)
    if not 0 < summary_start <= end - _FOOTER_BYTES:
        return False
    stream.seek(summary_start)
    crc = zlib.crc32(stream.read(end - 4 - summary_start))
    return crc == expected


def _unreadable(path: Path, size: int, exc: BaseException) -> str:
    if size == 0:
        return "empty file"
    if "magic" in type(exc).__name__.lower() or "magic" in str(exc).lower():
        return f"not an MCAP file, or truncated ({_describe(exc)})"
    return f"damaged MCAP file ({type(exc).__name__}: {_describe(exc)})"


@dataclass(frozen=True)
class Played:
    """One message to replay: its key, topic, log time and wire payload."""

    key: str
    topic: keys.Topic
    log_time_ns: int
    payload: bytes


class Recording:
    """A recording checked whole, ready to replay (`open_recording`)."""

    def __init__(self, info: BagInfo) -> None:
        self.info = info
        self.playable = {c.id: c for c in info.channels if c.topic is not None}
        self.unknown = [c for c in info.channels if c.skipped and c.skipped != DERIVED]

    def messages(self, *, start_ns: int | None = None,
                 only: Iterable[str] = ()) -> Iterator[Played]:
        """The replayed messages in log-time order, from `start_ns` on, only on
        keys matching one of the `only` expressions (all when empty)."""
        wanted = list(only)
        channel_ids = {cid for cid, c in self.playable.items()
                       if not wanted or any(key_matches(w, c.key) for w in wanted)}
        with open(self.info.path, "rb") as stream:
            reader = SeekingReader(stream, record_size_limit=mcap_records.MAX_RECORD_BYTES)
            try:
                for _schema, channel, message in reader.iter_messages(
                        start_time=start_ns, log_time_order=True):
                    if message.channel_id not in channel_ids:
                        continue
                    topic = self.playable[message.channel_id].topic
                    assert topic is not None
                    yield Played(channel.topic, topic, message.log_time,
                                 channels.from_json(topic, message.data))
            except (McapError, channels.ChannelError, Exception) as exc:
                raise BagError(f"{self.info.path}: changed while playing: "
                               f"{_describe(exc)}") from None

    def selected(self, only: Iterable[str]) -> list[ChannelInfo]:
        wanted = list(only)
        return [c for c in self.playable.values()
                if not wanted or any(key_matches(w, c.key) for w in wanted)]


def open_recording(path: str | Path) -> Recording:
    """Read a recording's summary and then every record, checking CRCs and
    converting every replayed message back to its payload; BagError naming
    the first problem. Nothing is kept in memory but the summary."""
    info = read_info(path)
    recording = Recording(info)
    counts: dict[int, int] = {}
    state = mcap_records.Walk()
    try:
        with open(info.path, "rb") as stream:
            for record in mcap_records.walk(stream, info.size, state):
                if not isinstance(record, McapMessage):
                    continue
                counts[record.channel_id] = counts.get(record.channel_id, 0) + 1
                channel = recording.playable.get(record.channel_id)
                if channel is not None and channel.topic is not None:
                    try:
                        channels.from_json(channel.topic, record.data)
                    except channels.ChannelError as exc:
                        raise BagError(f"{info.path}: message {sum(counts.values())} on "
                                       f"{channel.key} is not a valid {channel.schema}: "
                                       f"{_describe(exc)}") from None
    except mcap_records.TooLarge as exc:
        raise BagError(f"{info.path}: refused: {exc}") from None
    except (mcap_records.Damaged, OSError) as exc:
        raise BagError(f"{info.path}: damaged after message {sum(counts.values())} "
                       f"({_describe(exc)}); refusing to play any of it") from None
    if not state.data_end:
        raise BagError(f"{info.path}: no end of data: truncated; refusing to play it")
    if any(state.chunks is None or state.chunks.get(start) != length
           for start, length in info.chunk_spans):
        raise BagError(f"{info.path}: its index points outside the chunks it holds: "
                       "damaged; refusing to play it")
    expected = {c.id: c.count for c in info.channels if c.count}
    if counts != expected or sum(counts.values()) != info.messages:
        raise BagError(f"{info.path}: the summary counts {info.messages} messages but the "
                       f"file holds {sum(counts.values())}: damaged; refusing to play it")
    return recording


# --- timing -------------------------------------------------------------------------


def schedule_s(log_time_ns: int, first_ns: int, rate: float) -> float:
    """Seconds after the replay's start at which a message is due: its log time
    relative to the first replayed message, divided by the rate."""
    if rate <= 0:
        raise ValueError("rate must be positive")
    return max(0, log_time_ns - first_ns) / 1e9 / rate
