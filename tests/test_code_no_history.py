"""The code tells what it does and why, never a reference its reader cannot open.

The Python files of services/, tests/ and benchmarks/ are read as text
(comments, docstrings, strings and all): a tracker's issue number, or an
explanation by the earlier ROS 2 design this robot rebuilds (the
project's word for it: "seed"), sends the reader somewhere they cannot
follow. Where
a ROS 2 name is kept for compatibility, the code says so ("the ROS 2
name"). The history phrases of tests/test_docs_no_history.py apply too.

"seed" is also a random-number seed (`seed: int = 1`, `Random(seed)`, "the
same seed gives the same events"): only the forms below, which a random
seed does not take, are flagged.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.test_docs_no_history import HISTORY

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted(p for folder in ("services", "tests", "benchmarks")
               for p in (ROOT / folder).rglob("*.py"))
S = "[Ss]" + "eed"  # in pieces, so this file does not match itself
SEED = [
    rf"\b{S}'s\b",  # possessive: the design's own things
    r"\b[Tt]he s" + r"eed\b(?!\s*(?:=|is\b|of\b|for\b|value\b|number\b))",  # not "the s. is 3"
    rf"\b{S}:[ \t]+[A-Za-z]+[ \t]+[A-Za-z]",  # a note, not an annotation (`: int = 1`)
    rf"\b{S} [a-z][a-z0-9]*_\w+",  # a ROS 2 node's name
    rf"\b{S} (?:mode|behaviou?r|rules?|design|names?|topics?|fields?|typos?|nodes?|robot)\b",
]
PATTERN = re.compile("|".join(f"(?:{p})" for p in [*HISTORY, *SEED]))
EXEMPT: dict[str, str] = {}
"""Temporarily unchecked files (path: why); strict, an entry that no longer hits fails."""


def hits(text: str) -> list[str]:
    """`line: text` of each line pointing at an issue, the earlier design or history."""
    return [f"{n}: {line.strip()}" for n, line in enumerate(text.splitlines(), 1)
            if PATTERN.search(line)]


def _name(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def test_the_files_are_found() -> None:
    names = {_name(p) for p in FILES}
    assert {"services/contract/keys.py", "tests/conftest.py", "benchmarks/common.py",
            "tests/test_code_no_history.py"} <= names


@pytest.mark.parametrize("path", FILES, ids=_name)
def test_the_code_says_what_is(path: Path) -> None:
    found = hits(path.read_text())
    if _name(path) in EXEMPT:
        assert found, f"{_name(path)} no longer hits: remove it from EXEMPT"
        return
    assert not found, ("an issue number, the earlier design or history (say what the code "
                       "does and why, in the present tense):\n" + "\n".join(found))


def test_exempt_files_exist() -> None:
    missing = [name for name in EXEMPT if not (ROOT / name).is_file()]
    assert not missing, f"gone, remove from EXEMPT: {missing}"


W = "s" + "eed"


@pytest.mark.parametrize("text", [
    "the raw session stays private (is" "sue 16)", "see Is" "sue #3",
    f"a path, the {W}'s camera_lld", f"A.EYE_AWAKE: EyePair.same(0.0, 0.0),  # {W}: fully open",
    f"(width of an adult face; {W}: face width)", f"the eyes driver ({W} eye_display_hld)",
    f"* {W.title()} mode: every timing 0", f"The {W} used a static transform",
    f"Trigger in the {W}). On success", f"presence rule: {W} rule, hysteresis",
    f"{W.title()}'s behaviour exactly", "gap w" "as 14 ms", "the o" "ld rule (1 s backoff)",
])
def test_references_and_history_are_caught(text: str) -> None:
    assert hits(text)


@pytest.mark.parametrize("text", [
    f"    {W}: int = 1", f"    {W}: int | None = None,",
    f"def walk(photo, frames: int, {W}: int = 20)",
    f"same {W} give the same events (the tests rely on it)", f"rng = random.Random(self.{W})",
    f"np.random.default_rng({W}).normal(size=DIM)", f'@pytest.mark.parametrize("{W}", range(20))',
    f"for u, v, {W} in POSITIONS:", f"SimulatedLD2450(angle, {W}={W},", f'tmp_path / "{W}.mcap"',
    f"the {W} is fixed, so the run repeats", f"the {W} of the generator",
    "an issue with the token", "the older stamp", f"lambda {W}: make({W})",
])
def test_random_seeds_and_ordinary_words_pass(text: str) -> None:
    assert not hits(text)
