"""The face photos the simulated camera draws, with where they come from (data/faces)."""

from __future__ import annotations

import functools
import tomllib
from importlib import resources
from pathlib import Path

import msgspec


class Face(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """One photo: its file, how much of it BlazeFace's box covers, and its licence."""

    file: str
    box_frac: float
    person: str
    source: str
    licence: str


def folder() -> Path:
    return Path(str(resources.files("buddybot.sim") / "data" / "faces"))


@functools.cache
def catalogue() -> dict[str, Face]:
    """Every shipped face by name (read once)."""
    raw = tomllib.loads((folder() / "faces.toml").read_text())
    return msgspec.convert(raw, dict[str, Face])


def names() -> list[str]:
    return sorted(catalogue())


def path(name: str) -> Path:
    return folder() / catalogue()[name].file
