"""`buddybot.audio.tts`: the cache of rendered speech stays bounded (any text may be
spoken), keeping the most recently used files."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from buddybot.audio import tts


def test_prune_keeps_the_most_recently_used_files(tmp_path: Path) -> None:
    for i in range(6):
        path = tmp_path / f"{i}.wav"
        path.write_bytes(b"x" * 64)
        os.utime(path, ns=(i * 10**9, i * 10**9))
    (tmp_path / "notes.txt").write_text("not a rendering")
    assert tts.prune(tmp_path, 4) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "2.wav", "3.wav", "4.wav", "5.wav", "notes.txt"]


@pytest.mark.skipif(shutil.which("espeak-ng") is None,
                    reason="espeak-ng not installed (scripts/test-packages.sh installs it)")
def test_rendering_many_texts_keeps_the_cache_bounded(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tts, "CACHE_FILES", 3)
    first = tts.render("one", folder=tmp_path)
    for text in ("two", "three", "four"):
        tts.render(text, folder=tmp_path)
    assert len(list(tmp_path.glob("*.wav"))) == 3 and not first.exists()
    again = tts.render("one", folder=tmp_path)
    assert again.exists() and again.stat().st_size > 44
