"""Cut recordings copied up to their last complete chunk, without processes."""

from __future__ import annotations

from pathlib import Path

import pytest

from buddybot.tools import bag, bag_recover
from tests.tools.mcap_bomb import write_bomb
from tests.tools.test_bag import samples, write_recording


def recording(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, n: int = 300) -> Path:
    monkeypatch.setattr(bag, "CHUNK_BYTES", 4096)
    path = tmp_path / "whole.mcap"
    key, (_topic, payload) = next((k, v) for k, v in samples().items() if "frames" in k)
    write_recording(path, [(key, payload, 1_000_000 + i) for i in range(n)])
    return path


def test_a_cut_file_is_copied_up_to_its_last_complete_chunk(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    whole = recording(tmp_path, monkeypatch)
    data = whole.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(bag.BagError, match="truncated"):
        bag.open_recording(cut)
    fixed = tmp_path / "fixed.mcap"
    found = bag_recover.recover(cut, fixed)
    assert 0 < found.messages < 300 and found.cut_bytes > 0 and not found.finished
    played = list(bag.open_recording(fixed).messages())
    assert len(played) == found.messages
    assert [p.log_time_ns for p in played] == [1_000_000 + i for i in range(found.messages)]
    assert bag.read_info(fixed).metadata["robot"] == "buddy"


def test_a_whole_file_is_copied_whole_and_a_bomb_refused(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    whole = recording(tmp_path, monkeypatch)
    found = bag_recover.recover(whole, tmp_path / "copy.mcap")
    assert found.messages == 300 and found.finished
    bomb = tmp_path / "bomb.mcap"
    write_bomb(bomb, 1 << 30)
    with pytest.raises(bag.BagError, match="refused: a chunk of"):
        bag_recover.recover(bomb, tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists()
    with pytest.raises(bag.BagError, match="another file"):
        bag_recover.recover(whole, whole)
    (tmp_path / "text.mcap").write_text("hello")
    with pytest.raises(bag.BagError, match="not an MCAP file"):
        bag_recover.scan(tmp_path / "text.mcap")
