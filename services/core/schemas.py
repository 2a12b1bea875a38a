"""Generate `schemas/`: JSON Schema of every message and the key table.

The files are derived from the msgspec types and the key catalogue, so
non-Python peers (an ESP32, a web page) can build against them; a test
regenerates them and fails when the committed copy has drifted.
"""

from __future__ import annotations

import json
from pathlib import Path

import msgspec

from buddybot.core import keys
from buddybot.core import messages as m


def generate() -> dict[str, str]:
    """File name (relative to schemas/) -> content."""
    files: dict[str, str] = {}
    for msg_type in m.ALL_MESSAGES:
        schema = msgspec.json.schema(msg_type)
        files[f"messages/{msg_type.__name__}.json"] = json.dumps(schema, indent=2, sort_keys=True)
    files["keys.json"] = json.dumps(keys.key_table(), indent=2)
    return {name: text + "\n" for name, text in files.items()}


def write(out: Path) -> list[Path]:
    written = []
    for name, text in generate().items():
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        written.append(path)
    return written


def drift(out: Path) -> list[str]:
    """Names of files that are missing, stale, or no longer generated."""
    expected = generate()
    problems = [n for n, t in expected.items()
                if not (out / n).exists() or (out / n).read_text() != t]
    if out.exists():
        for path in out.rglob("*.json"):
            rel = path.relative_to(out).as_posix()
            if rel not in expected:
                problems.append(rel)
    return sorted(problems)
