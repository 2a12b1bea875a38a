"""No tracked file points at documents outside the repository.

The design contract is docs/design.md, inside the repository; a file next
to the repository is one a new user does not have. This test fails when
any tracked text file names the shared design file outside it, or a
section of it, or section numbers of the documents of the earlier ROS 2
design.

The tracked files are read from the git index itself (a tiny reader of the
index format, versions 2 and 3), not from `git ls-files`: a unit test starts
no process. Without a git checkout (an unpacked source archive) every file
of the tree outside ignored folders is checked instead.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Spelled in pieces so this file does not match itself.
# Across line breaks: a reference wrapped by the text's line length still counts.
FORBIDDEN = re.compile("|".join((
    re.escape("shared/" + "DESIGN.md"),
    re.escape("DESIGN.md") + r"\s+sections?\b",
    re.escape("../" + "shared"),
    "[Ss]eed" + r"\s+(?:section\s+)?\d+\.\d",  # "seed 5.4.3", "Seed section 4.3.1"
)))
SKIP_DIRS = {".git", ".venv", "__pycache__", "test-artifacts", ".pytest_cache",
             ".ruff_cache", ".mypy_cache", ".hypothesis", "build", "dist"}


def index_paths(index: Path) -> list[str] | None:
    """Paths in a git index (format 2 or 3), or None when it cannot be read."""
    data = index.read_bytes()
    if len(data) < 12 or data[:4] != b"DIRC":
        return None
    version, count = struct.unpack(">II", data[4:12])
    if version not in (2, 3):
        return None
    paths, pos = [], 12
    for _ in range(count):
        flags = struct.unpack(">H", data[pos + 60:pos + 62])[0]
        start = pos + 62 + (2 if version == 3 and flags & 0x4000 else 0)
        end = data.index(b"\0", start)
        paths.append(data[start:end].decode("utf-8", "surrogateescape"))
        pos += ((end - pos) // 8 + 1) * 8  # entries are NUL-padded to a multiple of 8
    return paths


def tracked_files() -> list[Path]:
    index = ROOT / ".git" / "index"
    paths = index_paths(index) if index.is_file() else None
    if paths is not None:
        return [ROOT / p for p in paths]
    return [p for p in ROOT.rglob("*") if p.is_file()
            and not SKIP_DIRS & set(p.relative_to(ROOT).parts)
            and not any(part.endswith(".egg-info") for part in p.parts)]


def test_the_index_reader_finds_this_repository_s_files() -> None:
    files = {p.relative_to(ROOT).as_posix() for p in tracked_files()}
    assert {"README.md", "services/contract/keys.py", "pyproject.toml"} <= files


def test_the_pattern_catches_what_it_must() -> None:
    for bad in ("see ../" "shared/DESIGN.md", "DESIGN.md" " section 2", "Seed section 4.3.1",
                "(seed 5.4.3)", "(seed\nsection 5.3", "DESIGN.md" "\nsections 2"):
        assert FORBIDDEN.search(bad), bad
    for fine in ("docs/design.md section 2", "the s" "eed's rule", "seed=3"):
        assert not FORBIDDEN.search(fine), fine


def test_no_tracked_text_file_points_outside_the_repository() -> None:
    found = []
    for path in tracked_files():
        if not path.is_file():
            continue  # deleted in the working tree, not yet in the index
        if path.resolve() == Path(__file__).resolve():
            continue  # this file spells the patterns out in its own examples
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary
        text = data.decode("utf-8", "replace")
        for match in FORBIDDEN.finditer(text):
            number = text.count("\n", 0, match.start()) + 1
            found.append(f"{path.relative_to(ROOT)}:{number}: {' '.join(match.group(0).split())}")
    assert not found, ("references to documents outside the repository (use docs/design.md):\n"
                       + "\n".join(found))
