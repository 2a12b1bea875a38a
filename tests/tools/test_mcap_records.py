"""Bounded MCAP reading without processes: limits checked before memory is spent."""

from __future__ import annotations

from pathlib import Path

import pytest
import zstandard
from mcap.records import Chunk, Message

from buddybot.tools import bag, mcap_records
from tests.tools.mcap_bomb import write_bomb
from tests.tools.test_bag import samples, write_recording


def _chunk(data: bytes, declared: int) -> Chunk:
    return Chunk(compression="zstd", data=zstandard.ZstdCompressor().compress(data),
                 message_start_time=0, message_end_time=0, uncompressed_crc=0,
                 uncompressed_size=declared)


def test_a_chunk_over_the_limit_is_refused_from_its_declared_size() -> None:
    with pytest.raises(mcap_records.TooLarge, match="a chunk of 101 bytes is over"):
        mcap_records.decompress(_chunk(b"x" * 101, 101), limit=100)


def test_a_chunk_holding_more_than_it_declares_is_damaged() -> None:
    """The zstd frame's own size (1 MB) is not believed over the chunk's (10)."""
    with pytest.raises(mcap_records.Damaged, match="declares 10 bytes but holds more"):
        mcap_records.decompress(_chunk(bytes(1 << 20), 10))
    with pytest.raises(mcap_records.Damaged, match="declares 10 bytes but holds 5"):
        mcap_records.decompress(_chunk(b"12345", 10))


def test_a_bomb_is_refused_while_walking(tmp_path: Path) -> None:
    path = tmp_path / "bomb.mcap"
    size = write_bomb(path, mcap_records.MAX_CHUNK_BYTES)
    with open(path, "rb") as stream, pytest.raises(mcap_records.TooLarge):
        list(mcap_records.walk(stream, size, mcap_records.Walk()))


def test_a_good_recording_walks_to_its_end(tmp_path: Path) -> None:
    path = tmp_path / "good.mcap"
    items = [(key, payload, 1_000 + i) for i, (key, (_t, payload))
             in enumerate(samples().items())]
    write_recording(path, items)
    state = mcap_records.Walk()
    with open(path, "rb") as stream:
        found = [r for r in mcap_records.walk(stream, path.stat().st_size, state)
                 if isinstance(r, Message)]
    assert len(found) == len(items) + 1  # and the faces' derived annotations
    assert state.data_end and state.chunks


def test_a_cut_file_walks_to_its_last_complete_chunk(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bag, "CHUNK_BYTES", 2048)
    path = tmp_path / "good.mcap"
    key, (_topic, payload) = next(iter(samples().items()))
    write_recording(path, [(key, payload, 1_000 + i) for i in range(200)])
    whole = mcap_records.Walk()
    with open(path, "rb") as stream:
        list(mcap_records.walk(stream, path.stat().st_size, whole))
    starts = sorted(whole.chunks or {})
    assert len(starts) > 3
    data = path.read_bytes()[:starts[3] + 100]  # cut inside the fourth chunk
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data)
    state = mcap_records.Walk()
    with open(cut, "rb") as stream:
        found = [r for r in mcap_records.walk(stream, len(data), state,
                                              stop_at_damage=True) if isinstance(r, Message)]
    assert sorted(state.chunks or {}) == starts[:3] and not state.data_end
    assert 0 < len(found) < 200 and state.good_end <= starts[3]
