"""The set-up's size and time come from scripts/setup.sh, not from prose.

The script measures both and prints them on its last line (`.venv ready for
PROFILE: N MB, set up in N s`); a figure written into a page is true for one
machine on one day. So the pages that tell a reader about the install quote
that line, and hold no size or install time of their own.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SETUP = ROOT / "scripts" / "setup.sh"
PAGES = [ROOT / "README.md", ROOT / "docs" / "README.md", ROOT / "docs" / "tutorial.md",
         *sorted((ROOT / "docs" / "howto").glob("*.md"))]
"""The guide: the pages a newcomer installs from."""
INSTALL = re.compile(r"\binstall|setup\.sh|run\.sh|\.venv", re.IGNORECASE)
SIZE = re.compile(r"\b\d[\d.,]*\s*(?:[KMG]i?B|[KMG])\b")
TIME = re.compile(r"\b\d+(?:\s*[-–]\s*\d+)?\s*(?:s|sec|seconds?|min|minutes?)\b")
READY = ".venv ready for"


def install_figures(text: str) -> list[str]:
    """Sizes and times in the paragraphs of `text` that speak of installing."""
    found = []
    for paragraph in re.split(r"\n\s*\n", text):
        if INSTALL.search(paragraph) and re.search(r"\binstall", paragraph, re.IGNORECASE):
            found += SIZE.findall(paragraph) + TIME.findall(paragraph)
    return found


def test_the_script_measures_and_prints_size_and_time() -> None:
    script = SETUP.read_text()
    [line] = [x for x in script.splitlines() if READY in x and x.lstrip().startswith("say")]
    assert "du -sm .venv" in line and "SECONDS - start" in line, line
    assert "MB" in line and " s\"" in line, line


@pytest.mark.parametrize("text", [
    "The first run installs the runtime (about 370 MB,\n20-50 s; one progress line)",
    "The first run installs the `test` extra into `.venv` (about 950 MB in all)",
    "scripts/setup.sh installs everything in 2 minutes",
])
def test_the_rule_finds_hard_coded_figures(text: str) -> None:
    assert install_figures(text), text


def test_the_guide_quotes_the_scripts_line_instead_of_figures() -> None:
    bad = {p.relative_to(ROOT).as_posix(): found for p in PAGES
           if (found := install_figures(p.read_text()))}
    assert not bad, f"figures the set-up script measures itself: {bad}"
    tutorial = (ROOT / "docs" / "tutorial.md").read_text()
    assert READY in re.sub(r"\s+", " ", tutorial), "the tutorial quotes the script's last line"
