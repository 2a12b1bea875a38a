"""The guide tells what the code is, never its history.

docs/ is read by builders: a figure in the past tense, a tracker's issue
number, what came before a fix tell them nothing they can use, and go stale with
every change (git log keeps the history). A small list of phrases that
only history uses; "before the first message", "the older stamp" and the
like stay legal. tests/test_code_no_history.py applies them to the code.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").rglob("*.md"))
HISTORY = [
    r"\b[Ii]ssues? #?\d+",  # a tracker's issue number, with or without '#'
    r"\b(?:[Bb]efore|[Uu]ntil|[Ss]ince|[Aa]fter) the (?:fix|fixes|rewrite|change)\b",
    r"\b[Pp]reviously\b",
    r"\b[Ff]ormerly\b",
    r"\bwas (?:about |~)?\d[\d.,]* ?(?:ms|s|us|µs|%|MB|kB|GB|fps|Hz)\b",  # a past figure
    r"\b[Tt]he old (?:rule|code|behaviou?r|version|way)\b",
    r"\b(?:[Ii]t|[Tt]hey|[Tt]his|[Tt]hat) used to\b",
    r"\b[Ii]t no longer\b",
]
PATTERN = re.compile("|".join(f"(?:{p})" for p in HISTORY))


def history_in(text: str) -> list[str]:
    """`line: text` of each line telling the code's history."""
    return [f"{n}: {line.strip()}" for n, line in enumerate(text.splitlines(), 1)
            if PATTERN.search(line)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_history_of_the_code(page: Path) -> None:
    found = history_in(page.read_text())
    assert not found, "history of the code (say what is, not what was):\n" + "\n".join(found)


@pytest.mark.parametrize("text", [
    # In pieces, so this file passes tests/test_code_no_history.py.
    "Fixed in is" "sue 12.", "p95 w" "as 6.8 ms", "Bef" "ore the fix a frame froze.",
    "Previous" "ly it blocked.", "It us" "ed to search the buffer.",
    "the o" "ld rule left goals refused", "It no" " longer depends on the token.",
])
def test_history_is_caught(text: str) -> None:
    assert history_in(text)


@pytest.mark.parametrize("text", [
    "before the first message", "a face older than this no longer counts as seen",
    "the older stamp is dropped", "used to draw the eyes", "it was refused", "was 3 frames",
])
def test_ordinary_words_pass(text: str) -> None:
    assert not history_in(text)
