"""Recordings cut short (kill -9, a power cut, a full disk), read up to their last complete chunk.

The recorder writes each chunk whole as it fills, so what a killed
recorder leaves is a valid data section cut somewhere after its last
complete chunk, without the summary and index that `bag info`/`play` and
Foxglove need. Rather than teach every reader to guess (and `play` to
accept a half-copied file without saying so), `bag recover IN -o OUT`
copies every complete record into a new, finished file, and says how much
was cut. Both the scan and the copy use the bounded walk of
`mcap_records`, so a hostile file costs no more than a good one. Pure:
files only, no Zenoh.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from buddybot.tools import mcap_records
from buddybot.tools.bag import CHUNK_BYTES, BagError


@dataclass(frozen=True)
class Salvage:
    """What a cut recording holds up to its last complete record."""

    messages: int
    readable_bytes: int
    """Bytes of the file up to the end of its last complete record."""
    size: int
    finished: bool
    """Whether the data section was complete (the file only lacked its summary, or nothing)."""

    @property
    def cut_bytes(self) -> int:
        return self.size - self.readable_bytes


def scan(path: str | Path) -> Salvage:
    """Count what `recover` would copy, without writing; BagError when `path`
    is not an MCAP file or a record is over the size limits."""
    return _copy(Path(path), None)


def recover(source: str | Path, output: str | Path) -> Salvage:
    """Copy every complete record of `source` into a new, finished `output`."""
    source, output = Path(source), Path(output)
    if output.exists() and output.resolve() == source.resolve():
        raise BagError(f"{output}: the output must be another file than the input")
    return _copy(source, output)


def _copy(source: Path, output: Path | None) -> Salvage:
    try:
        stream = open(source, "rb")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise BagError(f"{source}: cannot read: {exc.strerror or exc}") from None
    state = mcap_records.Walk()
    out = _Copier(output) if output is not None else None
    messages = 0
    channels: set[int] = set()
    try:
        with stream:
            size = os.fstat(stream.fileno()).st_size
            for record in mcap_records.walk(stream, size, state, stop_at_damage=True):
                if isinstance(record, Channel):
                    channels.add(record.id)
                elif isinstance(record, Message) and record.channel_id in channels:
                    messages += 1  # (one on a channel never declared cannot be replayed)
                if out is not None:
                    out.add(record)
    except (mcap_records.TooLarge, mcap_records.Damaged) as exc:
        if out is not None:
            out.abandon()
        refused = "refused: " if isinstance(exc, mcap_records.TooLarge) else ""
        raise BagError(f"{source}: {refused}{exc}") from None
    if out is not None:
        out.close()
    return Salvage(messages, state.good_end, size, state.data_end)


class _Copier:
    """Writes the records of a walk into a new MCAP file, ids remapped as the
    writer numbers them."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._stream = open(path, "wb")  # noqa: SIM115 (closed in close())
        except OSError as exc:
            raise BagError(f"{path}: cannot write: {exc.strerror or exc}") from None
        self._writer = Writer(self._stream, chunk_size=CHUNK_BYTES,
                              compression=CompressionType.ZSTD, enable_data_crcs=True)
        self._started = False
        self._schemas: dict[int, int] = {0: 0}
        self._channels: dict[int, int] = {}

    def _start(self, profile: str = "", library: str = "") -> None:
        if not self._started:
            self._writer.start(profile=profile, library=library or "buddybot bag recover")
            self._started = True

    def add(self, record: object) -> None:
        if isinstance(record, Header):
            self._start(record.profile, record.library)
            return
        self._start()
        if isinstance(record, Schema) and record.id not in self._schemas:
            self._schemas[record.id] = self._writer.register_schema(
                record.name, record.encoding, record.data)
        elif isinstance(record, Channel) and record.id not in self._channels:
            self._channels[record.id] = self._writer.register_channel(
                record.topic, record.message_encoding, self._schemas.get(record.schema_id, 0),
                dict(record.metadata))
        elif isinstance(record, Metadata):
            self._writer.add_metadata(record.name, dict(record.metadata))
        elif isinstance(record, Message) and record.channel_id in self._channels:
            self._writer.add_message(self._channels[record.channel_id], log_time=record.log_time,
                                     data=record.data, publish_time=record.publish_time,
                                     sequence=record.sequence)

    def abandon(self) -> None:
        """Remove the half-written output (the input was refused)."""
        self._stream.close()
        self.path.unlink(missing_ok=True)

    def close(self) -> None:
        try:
            self._start()
            self._writer.finish()
        except OSError as exc:
            raise BagError(f"{self.path}: cannot write: {exc.strerror or exc}") from None
        finally:
            self._stream.close()
