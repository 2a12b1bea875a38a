"""MCAP records read with bounds: sizes checked before anything is allocated or decompressed.

A recording is untrusted input: 34 kB of zstd can declare (and hold) a
1 GiB message, and the `mcap` library decompresses a chunk whole before
looking inside it. So the data section is walked here record by record:
each record's length is checked against `MAX_RECORD_BYTES` before its body
is read, each chunk's declared uncompressed size against `MAX_CHUNK_BYTES`
before it is decompressed, and decompression itself stops one byte past the
declared size (a zstd frame can claim one size in the chunk and another in
its own header). Pure: a file in, records out, no Zenoh.

The same walk serves `bag play`'s check and `bag recover`: it reports where
the last complete record ended, so a file cut by kill -9 or a full disk is
readable up to its last complete chunk.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import IO

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    Metadata,
    Schema,
)

from buddybot.contract import keys

MAGIC = b"\x89MCAP0\r\n"
MAX_MESSAGE_BYTES = 2 * keys.IMAGE_MESSAGE_BYTES
"""The largest message a recording may hold: the largest wire message (a camera
frame) as base64 JSON is about 4/3 of it, plus its envelope."""
MAX_CHUNK_BYTES = 2 * MAX_MESSAGE_BYTES
"""The largest uncompressed chunk: the recorder closes chunks at 1 MiB, so
this holds its largest message with room to spare."""
MAX_RECORD_BYTES = MAX_CHUNK_BYTES
"""The largest record read from the file (a chunk's compressed bytes, a metadata
or attachment record)."""
_RECORD_HEADER = 9


class TooLarge(ValueError):
    """A record, chunk or message over its limit; the text says which and by how much."""


class Damaged(ValueError):
    """A record that does not parse, or whose CRC does not match."""


@dataclass
class Walk:
    """Where a walk through a file got to."""

    good_end: int = 0
    """Offset just past the last complete, valid record of the data section."""
    data_end: bool = False
    """Whether the data section's DataEnd record was reached."""
    chunks: dict[int, int] | None = None
    """Offset -> length of every chunk checked (for matching the summary's index)."""


_PARSERS: dict[int, Callable[[ReadDataStream], McapRecord]] = {
    Opcode.HEADER: Header.read, Opcode.SCHEMA: Schema.read, Opcode.CHANNEL: Channel.read,
    Opcode.CHUNK: Chunk.read, Opcode.METADATA: Metadata.read,
    Opcode.ATTACHMENT: Attachment.read, Opcode.DATA_END: DataEnd.read,
    Opcode.FOOTER: Footer.read,
}


def _limit_text(what: str, size: int, limit: int) -> str:
    return f"{what} of {size} bytes is over the limit of {limit} bytes ({limit >> 20} MiB)"


def decompress(chunk: Chunk, limit: int = MAX_CHUNK_BYTES) -> bytes:
    """A chunk's records, decompressed to at most its declared size (itself at
    most `limit`); TooLarge or Damaged otherwise, before memory is spent."""
    declared = chunk.uncompressed_size
    if declared > limit:
        raise TooLarge(_limit_text("a chunk", declared, limit))
    if chunk.compression == "":
        data = chunk.data
    elif chunk.compression == "zstd":
        reader = zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data),
                                                             read_across_frames=True)
        try:
            data = reader.read(declared + 1) if declared else reader.read(1)
        except zstandard.ZstdError as exc:
            raise Damaged(f"a chunk does not decompress: {exc}") from None
    elif chunk.compression == "lz4":
        import lz4.frame  # type: ignore[import-untyped]  # optional, as in mcap itself
        try:
            data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data,
                                                                max_length=declared + 1)
        except RuntimeError as exc:
            raise Damaged(f"a chunk does not decompress: {exc}") from None
    else:
        raise Damaged(f"a chunk has unknown compression {chunk.compression!r}")
    if len(data) != declared:
        raise Damaged(f"a chunk declares {declared} bytes but holds "
                      f"{'more' if len(data) > declared else len(data)}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise Damaged("a chunk does not match its CRC")
    return data


def chunk_records(chunk: Chunk) -> Iterator[McapRecord]:
    """The schemas, channels and messages of a chunk, each record's length
    checked against MAX_MESSAGE_BYTES before it is read."""
    data = decompress(chunk)
    stream = ReadDataStream(io.BytesIO(data))
    while stream.count < len(data):
        opcode, length = _record_header(stream)
        if length > MAX_MESSAGE_BYTES:
            raise TooLarge(_limit_text("a message", length, MAX_MESSAGE_BYTES))
        if stream.count + length > len(data):
            raise Damaged("a record runs past the end of its chunk")
        body = stream.read(length)
        if opcode == Opcode.MESSAGE:
            yield Message.read(ReadDataStream(io.BytesIO(body)), length)
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL):
            yield _PARSERS[opcode](ReadDataStream(io.BytesIO(body)))


def _record_header(stream: ReadDataStream) -> tuple[int, int]:
    opcode, length = struct.unpack("<BQ", stream.read(_RECORD_HEADER))
    return int(opcode), int(length)


def walk(stream: IO[bytes], size: int, state: Walk, *, crc: bool = True,
         stop_at_damage: bool = False) -> Iterator[McapRecord]:
    """The data section's records in file order (chunks opened into their
    records), from the magic to DataEnd, each bounded as the module says.

    `state` tells how far the walk got. With `stop_at_damage` a truncated or
    damaged record ends the walk quietly (recovery); otherwise it raises
    Damaged (or TooLarge, always raised: a bomb is not a truncation)."""
    state.chunks = {}
    if stream.read(len(MAGIC)) != MAGIC:
        raise Damaged("not an MCAP file")
    state.good_end = position = len(MAGIC)
    running = zlib.crc32(MAGIC)
    while True:
        head = stream.read(_RECORD_HEADER)
        if len(head) < _RECORD_HEADER:
            if stop_at_damage:
                return
            raise Damaged(f"truncated at byte {position}")
        opcode, length = struct.unpack("<BQ", head)
        if length > MAX_RECORD_BYTES:
            raise TooLarge(_limit_text(f"a record at byte {position}", length,
                                       MAX_RECORD_BYTES))
        if position + _RECORD_HEADER + length > size:
            if stop_at_damage:
                return
            raise Damaged(f"truncated at byte {position}")
        body = stream.read(length)
        try:
            if opcode == Opcode.DATA_END:
                record = DataEnd.read(ReadDataStream(io.BytesIO(body)))
                if crc and record.data_section_crc and record.data_section_crc != running:
                    raise Damaged("the data section does not match its CRC")
                state.data_end = True
                state.good_end = position + _RECORD_HEADER + length
                return
            parser = _PARSERS.get(opcode)
            if opcode == Opcode.MESSAGE:
                if length > MAX_MESSAGE_BYTES:
                    raise TooLarge(_limit_text("a message", length, MAX_MESSAGE_BYTES))
                records: list[McapRecord] = [Message.read(ReadDataStream(io.BytesIO(body)),
                                                          length)]
            elif opcode == Opcode.CHUNK:
                chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
                records = list(chunk_records(chunk))
                state.chunks[position] = _RECORD_HEADER + length
            elif parser is not None:
                records = [parser(ReadDataStream(io.BytesIO(body)))]
            else:
                records = []  # indexes and unknown records: nothing to replay
        except TooLarge:
            raise
        except Exception as exc:  # struct, UTF-8, zstd: a damaged record
            if stop_at_damage:
                return
            raise Damaged(f"damaged record at byte {position} "
                          f"({type(exc).__name__}: {str(exc)[:200]})") from None
        running = zlib.crc32(body, zlib.crc32(head, running))
        position += _RECORD_HEADER + length
        state.good_end = position
        yield from records
