"""Generate `schemas/`: JSON Schema of every message and the key table.

The files are derived from the msgspec types and the key catalogue, so
non-Python peers (an ESP32, a web page) can build against them; a test
regenerates them and fails when the committed copy has drifted.
"""

from __future__ import annotations

import enum
import inspect
import json
from pathlib import Path
from typing import Any

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m


def generate() -> dict[str, str]:
    """File name (relative to schemas/) -> content."""
    files: dict[str, str] = {}
    for msg_type in m.ALL_MESSAGES:
        schema = json_schema(msg_type)
        files[f"messages/{msg_type.__name__}.json"] = json.dumps(schema, indent=2, sort_keys=True)
    files["keys.json"] = json.dumps(keys.key_table(), indent=2)
    return {name: text + "\n" for name, text in files.items()}


def json_schema(msg_type: type[m.Message]) -> dict[str, Any]:
    """msgspec's JSON Schema of `msg_type`, its descriptions dedented as `help()`
    shows a docstring (msgspec releases differ in whether they do it, and the
    committed files must not), with the enum members named."""
    schema = msgspec.json.schema(msg_type)
    for definition in [schema, *schema.get("$defs", {}).values()]:
        if isinstance(definition.get("description"), str):
            definition["description"] = inspect.cleandoc(definition["description"])
    return with_enum_names(schema)


def _int_enums() -> dict[str, type[enum.IntEnum]]:
    return {value.__name__: value for value in vars(m).values()
            if isinstance(value, type) and issubclass(value, enum.IntEnum)
            and value is not enum.IntEnum}


def with_enum_names(schema: dict[str, Any]) -> dict[str, Any]:
    """Name the members of every integer enum: the wire carries numbers, but
    people (and `buddybot pub`, `echo`) use names. `x-enum-names[i]` names
    `enum[i]`; the description says the same for readers of the schema."""
    enums = _int_enums()
    for name, definition in schema.get("$defs", {}).items():
        cls = enums.get(name)
        if cls is None or "enum" not in definition:
            continue
        members = {member.value: member.name for member in cls}
        names = [members[value] for value in definition["enum"]]
        definition["x-enum-names"] = names
        listing = ", ".join(f"{v} = {n}" for v, n in zip(definition["enum"], names, strict=True))
        doc = definition.get("description")
        definition["description"] = f"{doc} ({listing})" if doc else listing
        definition.setdefault("type", "integer")
    return schema


def write_files(out: Path, files: dict[str, str]) -> list[Path]:
    """Write generated `files` (name relative to `out` -> text) under `out`."""
    written = []
    for name, text in files.items():
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        written.append(path)
    return written


def stale_files(out: Path, files: dict[str, str], pattern: str = "*") -> list[str]:
    """Names of generated `files` that are missing or stale under `out`, and of
    files matching `pattern` there that are no longer generated."""
    problems = [n for n, t in files.items()
                if not (out / n).is_file() or (out / n).read_text() != t]
    if out.is_dir():
        for path in out.rglob(pattern):
            rel = path.relative_to(out).as_posix()
            if path.is_file() and rel not in files:
                problems.append(rel)
    return sorted(problems)


def write(out: Path) -> list[Path]:
    return write_files(out, generate())


def drift(out: Path) -> list[str]:
    """Names of files that are missing, stale, or no longer generated."""
    return stale_files(out, generate(), "*.json")
