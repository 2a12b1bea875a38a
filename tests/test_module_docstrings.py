"""A module docstring says what the module is for, in a few lines.

Limit: 25 lines, about what a reader takes in at a glance on opening the
file (half a screen), enough for the purpose, the key why and a pointer.
Longer rationale (measurements, alternatives weighed, protocol details)
belongs in the module's page in docs/, where it is read with its context
and kept true by the docs' tests; the docstring points to it ("Rationale:
docs/people.md, 'Fusion'"). Reads the files with `ast`, starts nothing.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIMIT = 25
FILES = sorted(p for folder in ("services", "benchmarks") for p in (ROOT / folder).rglob("*.py"))


def docstring_lines(source: str) -> int:
    """Lines of the module docstring (0 without one)."""
    doc = ast.get_docstring(ast.parse(source), clean=False)
    return len(doc.splitlines()) if doc is not None else 0


def too_long(files: list[Path], limit: int = LIMIT) -> list[str]:
    """`path: N lines` of each file whose module docstring is longer than `limit`."""
    found = []
    for path in files:
        name = path.relative_to(ROOT).as_posix()
        if (n := docstring_lines(path.read_text())) > limit:
            found.append(f"{name}: {n} lines")
    return found


def test_module_docstrings_are_short() -> None:
    found = too_long(FILES)
    assert not found, (f"module docstrings over {LIMIT} lines (keep the purpose and the key "
                       "why, move the rest to the module's docs/ page and point to it):\n"
                       + "\n".join(found))


def test_the_checker_can_fail() -> None:
    long_doc = '"""Title.\n\n' + "A line of rationale.\n" * 30 + '"""\n\nX = 1\n'
    assert docstring_lines(long_doc) == 32
    assert docstring_lines("X = 1\n") == 0
    assert docstring_lines('"""One line."""\n') == 1
    folder = ROOT / "services"
    assert too_long([folder / "contract" / "keys.py"], limit=1)  # every module has a title
    assert not too_long([folder / "contract" / "keys.py"], limit=1000)


def test_the_files_are_found() -> None:
    names = {p.relative_to(ROOT).as_posix() for p in FILES}
    assert {"services/contract/keys.py", "benchmarks/common.py"} <= names
