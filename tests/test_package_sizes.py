"""No package of services/ grows past 4,500 lines of Python.

A package (a folder of `services/`, a layer in `tests/test_layering.py`)
that one person cannot hold in mind is where concerns start to mix; past
the limit, what has a name of its own becomes a package of its own (as the
web surfaces' shared code left the runtime for `web`). Every line counts
(blank ones and docstrings too), over every `*.py` file of the folder and
its subfolders.
"""

from __future__ import annotations

from pathlib import Path

SERVICES = Path(__file__).resolve().parents[1] / "services"
MAX_LINES = 4500
"""Lines of Python a package may hold at most."""


def package_lines(root: Path) -> dict[str, int]:
    """Each package folder of `root` (a folder with `__init__.py`) -> its lines of Python."""
    return {folder.name: sum(len(path.read_bytes().splitlines())
                             for path in folder.rglob("*.py"))
            for folder in sorted(root.iterdir()) if (folder / "__init__.py").is_file()}


def oversized(root: Path, limit: int = MAX_LINES) -> list[str]:
    """One line per package of `root` holding more than `limit` lines of Python."""
    return [f"services/{name}/ holds {lines} lines of Python (at most {limit})"
            for name, lines in package_lines(root).items() if lines > limit]


def test_no_package_is_over_the_limit() -> None:
    sizes = package_lines(SERVICES)
    assert {"runtime", "web", "contract"} <= set(sizes)  # the count really ran
    bad = oversized(SERVICES)
    assert not bad, "\n".join(bad) + "\n(split a concern out into a package of its own)"


def test_the_checker_catches_an_oversized_package(tmp_path: Path) -> None:
    """The check itself can fail: lines in subfolders count, other files and
    folders without `__init__.py` do not, and the report names the package."""
    big = tmp_path / "big"
    (big / "inner").mkdir(parents=True)
    (big / "__init__.py").write_text("")
    (big / "a.py").write_text("x = 1\n" * 6)
    (big / "inner" / "b.py").write_text("y = 2\n" * 5)
    (big / "notes.txt").write_text("text\n" * 100)
    small = tmp_path / "small"
    small.mkdir()
    (small / "__init__.py").write_text('"""Small."""\n')
    data = tmp_path / "data"
    data.mkdir()
    (data / "gen.py").write_text("z = 3\n" * 100)
    assert package_lines(tmp_path) == {"big": 11, "small": 1}
    assert oversized(tmp_path, limit=10) == [
        "services/big/ holds 11 lines of Python (at most 10)"]
    assert oversized(tmp_path, limit=11) == []
