"""A hostile recording: a small MCAP whose one zstd chunk holds a huge message.

Built record by record (the `mcap` writer would need the message in memory),
with a proper summary, so it passes every check that reads only the summary.
"""

from __future__ import annotations

from pathlib import Path

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    Schema,
    Statistics,
)

from buddybot.contract import channels, keys
from buddybot.tools import bag

MAGIC = b"\x89MCAP0\r\n"
PIECE = 1 << 20


def _zstd_message(size: int, log_time: int) -> tuple[bytes, int]:
    """A message record of `size` zero bytes on channel 1, zstd-compressed
    piece by piece; (compressed, uncompressed size)."""
    body_length = 2 + 4 + 8 + 8 + size
    total = 9 + body_length
    head = (bytes([0x05]) + body_length.to_bytes(8, "little") + (1).to_bytes(2, "little")
            + (0).to_bytes(4, "little") + log_time.to_bytes(8, "little") * 2)
    compressor = zstandard.ZstdCompressor(level=3, write_content_size=True).compressobj(
        size=total)
    out = [compressor.compress(head)]
    zeros = bytes(PIECE)
    left = size
    while left:
        n = min(PIECE, left)
        out.append(compressor.compress(zeros[:n]))
        left -= n
    out.append(compressor.flush())
    return b"".join(out), total


def write_bomb(path: Path, message_bytes: int, robot: str = "buddy") -> int:
    """Write the file; its size in bytes."""
    topic = keys.PRESENCE
    key = keys.absolute(robot, topic.key())
    ch = channels.channel(topic)
    log_time = 1_700_000_000_000_000_000
    schema = Schema(id=1, name=ch.schema_name, encoding=channels.SCHEMA_ENCODING,
                    data=ch.schema)
    channel = Channel(id=1, topic=key, message_encoding=ch.message_encoding, schema_id=1,
                      metadata={"encoding": topic.encoding})
    data, uncompressed = _zstd_message(message_bytes, log_time)
    b = RecordBuilder()
    b.write(MAGIC)
    Header(profile="", library="bomb").write(b)
    Metadata(name=bag.METADATA_NAME, metadata={"robot": robot, "version": "0"}).write(b)
    schema.write(b)
    channel.write(b)
    chunk_start = b.count
    Chunk(compression="zstd", data=data, message_start_time=log_time,
          message_end_time=log_time, uncompressed_crc=0,
          uncompressed_size=uncompressed).write(b)
    chunk_length = b.count - chunk_start
    DataEnd(data_section_crc=0).write(b)
    summary_start = b.count
    schema.write(b)
    channel.write(b)
    Statistics(attachment_count=0, channel_count=1, channel_message_counts={1: 1},
               chunk_count=1, message_count=1, message_end_time=log_time,
               message_start_time=log_time, metadata_count=1, schema_count=1).write(b)
    ChunkIndex(chunk_length=chunk_length, chunk_start_offset=chunk_start, compression="zstd",
               compressed_size=len(data), message_end_time=log_time, message_index_length=0,
               message_index_offsets={}, message_start_time=log_time,
               uncompressed_size=uncompressed).write(b)
    Footer(summary_start=summary_start, summary_offset_start=0, summary_crc=0).write(b)
    b.write(MAGIC)
    blob = b.end()
    path.write_bytes(blob)
    return len(blob)
