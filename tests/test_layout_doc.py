"""docs/layout.md names real files: every path it gives exists in the repository."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "docs" / "layout.md"
PATH = re.compile(r"`((?:services|tests)/[\w/.-]+)`")


def named_paths(text: str) -> list[str]:
    """Every `services/...` or `tests/...` path between backticks."""
    return PATH.findall(text)


def test_the_layout_page_names_paths() -> None:
    assert len(named_paths(LAYOUT.read_text())) > 40


def test_every_path_on_the_layout_page_exists() -> None:
    missing = [p for p in named_paths(LAYOUT.read_text()) if not (ROOT / p).exists()]
    assert not missing, f"docs/layout.md names paths that do not exist: {missing}"


def test_a_missing_path_is_caught() -> None:
    assert named_paths("see `services/runtime/nowhere.py` and `tests/x/`") == [
        "services/runtime/nowhere.py", "tests/x/"]
