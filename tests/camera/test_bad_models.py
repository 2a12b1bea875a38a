"""A model file LiteRT cannot load, or with the wrong tensor layout: the running
`face-detector` exits 2, naming the file and the layout it expected (processes)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.camera import models
from buddybot.tools.testing import Process, retry_until

pytestmark = pytest.mark.integration

Spawn = Callable[..., Process]


def refused(spawn: Spawn, *args: str) -> str:
    proc = spawn("face-detector", *args)
    retry_until(lambda: not proc.alive(), timeout=60, what="the detector refusing its model")
    assert proc.proc.returncode == 2, proc.output()
    return proc.output()


@pytest.mark.parametrize("content", [b"", b"\x00garbage, not a flatbuffer" * 40],
                         ids=["empty", "garbage"])
def test_a_file_litert_cannot_load(spawn: Spawn, tmp_path: Path, content: bytes) -> None:
    bad = tmp_path / "broken_model.tflite"
    bad.write_bytes(content)
    out = refused(spawn, "--model-path", str(bad))
    assert "broken_model.tflite" in out and "cannot load model" in out
    assert "1x192x192x3" in out  # what a full-range model would have been


def test_a_model_of_another_layout(spawn: Spawn) -> None:
    """The short-range model given where a full-range one is expected."""
    short = models.locate("short")
    out = refused(spawn, "--model", "full_sparse", "--model-path", str(short))
    assert short.name in out and "wrong tensor layout" in out
    assert "expected input 1x192x192x3" in out and "1x128x128x3" in out


def test_the_full_range_model_given_as_short(spawn: Spawn) -> None:
    full = models.locate("full_sparse")
    out = refused(spawn, "--model", "short", "--model-path", str(full), "--no-refine")
    assert full.name in out and "expected input 1x128x128x3" in out
