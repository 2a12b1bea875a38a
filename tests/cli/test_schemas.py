"""`buddybot schemas`: write the JSON Schemas, `--check` them."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli.process import bb

pytestmark = pytest.mark.integration


def test_schemas_check(tmp_path: Path) -> None:
    assert bb("schemas", "--out", str(tmp_path)).returncode == 0
    assert bb("schemas", "--check", "--out", str(tmp_path)).returncode == 0
    (tmp_path / "keys.json").write_text("[]")
    result = bb("schemas", "--check", "--out", str(tmp_path))
    assert result.returncode == 1 and "keys.json" in result.stderr
