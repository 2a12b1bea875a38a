"""A scenario file: who walks where and when, in the robot's frame (pure data + loading).

A scenario is a small TOML file (see docs/simulation.md): people with a
face photo and a path of timed waypoints, static clutter the radar sees,
and whether the run loops. Coordinates are the robot's (ROS axes, metres,
origin under the camera): x forward, y left. Loading checks everything a
run would trip over later (unknown keys, unknown photos, paths that go
back in time, more people than the bounds allow, absurd times) and names
the key and the line of the file in one `ScenarioError`.
"""

from __future__ import annotations

import re
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Literal

import msgspec

from buddybot.runtime import nesting
from buddybot.sim import faces

MAX_PEOPLE = 8
"""People one scenario may hold (the LD2450 reports 3, the camera draws them all)."""
MAX_WAYPOINTS = 64
MAX_LENGTH_S = 24 * 3600.0
"""Longest scenario: a day. Longer is a typo, not a test."""
MAX_FILE_BYTES = 64 * 1024

Facing = Literal["robot", "path", "away"]
"""Where a person looks: at the robot, where they walk, or away from the robot."""

Metres = Annotated[float, msgspec.Meta(ge=-50.0, le=50.0)]


class ScenarioError(ValueError):
    """A scenario that cannot run: the message names the file, key and line."""


class Waypoint(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Where a person is at scenario time `t` (s); straight lines in between."""

    t: Annotated[float, msgspec.Meta(ge=0.0, le=MAX_LENGTH_S)]
    x: Metres
    y: Metres
    facing: Facing | None = None
    """None: as at the previous waypoint (the first defaults to "robot")."""


class PersonSpec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """One person: a face photo, an eye height and a path."""

    face: str
    name: Annotated[str, msgspec.Meta(max_length=64)] = ""
    """Who they are, for tests that check names; empty: a stranger."""
    height_m: Annotated[float, msgspec.Meta(ge=0.5, le=2.5)] = 1.2
    """Eye height above the floor (1.2 m: seated or leaning at a desk)."""
    path: Annotated[list[Waypoint], msgspec.Meta(min_length=1, max_length=MAX_WAYPOINTS)]


class ClutterSpec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Something the radar sees that is not a person: a fan (moving) or a ghost (still)."""

    kind: Literal["fan", "ghost"]
    x: Metres
    y: Metres
    until_s: Annotated[float, msgspec.Meta(ge=0.0, le=MAX_LENGTH_S)] | None = None
    """Gone from this scenario time on (None: always there)."""


class ScenarioSpec(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """The whole file."""

    description: Annotated[str, msgspec.Meta(min_length=1, max_length=400)]
    length_s: Annotated[float, msgspec.Meta(gt=0.0, le=MAX_LENGTH_S)]
    loop: bool = False
    """Start over after `length_s` (the default `visit`); else stay at the end."""
    camera_height_m: Annotated[float, msgspec.Meta(ge=0.1, le=2.5)] = 1.0
    camera_covered: bool = False
    """The camera sees nothing (a hand or a cap over it): the radar alone."""
    person: Annotated[list[PersonSpec], msgspec.Meta(max_length=MAX_PEOPLE)] = []
    clutter: Annotated[list[ClutterSpec], msgspec.Meta(max_length=8)] = []


class Scenario(msgspec.Struct, frozen=True):
    """A checked scenario and where it came from."""

    name: str
    spec: ScenarioSpec
    source: str


def builtin_names() -> list[str]:
    """The scenarios shipped with BuddyBot, by name (`buddybot sim list`)."""
    folder = resources.files("buddybot.sim") / "scenarios"
    return sorted(p.name.removesuffix(".toml") for p in folder.iterdir()
                  if p.name.endswith(".toml"))


def builtin_path(name: str) -> Path:
    return Path(str(resources.files("buddybot.sim") / "scenarios" / f"{name}.toml"))


def load(name_or_path: str) -> Scenario:
    """A built-in scenario by name, else a file by path; ScenarioError when it cannot run."""
    if name_or_path in builtin_names():
        path = builtin_path(name_or_path)
    else:
        path = Path(name_or_path)
        if not path.suffix and not path.exists():
            raise ScenarioError(f"{name_or_path}: no such scenario; built in: "
                                f"{', '.join(builtin_names())}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read: {exc.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise ScenarioError(f"{path}: {len(data)} bytes; a scenario is at most "
                            f"{MAX_FILE_BYTES}")
    return parse(data.decode("utf-8", "replace"), str(path), path.stem)


def parse(text: str, source: str = "<scenario>", name: str = "scenario") -> Scenario:
    """Decode and check TOML text (see `load`)."""
    try:
        nesting.check_depth(text, toml=True)  # tomllib recurses on nesting
        raw = tomllib.loads(text)
    except nesting.TooDeep as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    try:
        spec = msgspec.convert(raw, ScenarioSpec)
    except msgspec.ValidationError as exc:
        key, reason = _split(str(exc))
        raise ScenarioError(_where(source, text, key) + reason) from None
    for problem, key in _problems(spec):
        raise ScenarioError(_where(source, text, key) + problem)
    return Scenario(name, spec, source)


def _problems(spec: ScenarioSpec) -> list[tuple[str, str]]:
    """What the types cannot say: unknown photos, time order, paths past the end."""
    found: list[tuple[str, str]] = []
    known = faces.names()
    for i, person in enumerate(spec.person):
        if person.face not in known:
            found.append((f"unknown face {person.face!r}; one of {', '.join(known)}",
                          f"person[{i}].face"))
        times = [w.t for w in person.path]
        for j in range(1, len(times)):
            if times[j] <= times[j - 1]:
                found.append((f"t = {times[j]:g} is not after the previous waypoint's "
                              f"{times[j - 1]:g}", f"person[{i}].path[{j}].t"))
        if times[-1] > spec.length_s:
            found.append((f"t = {times[-1]:g} is after the scenario's end "
                          f"(length_s = {spec.length_s:g})",
                          f"person[{i}].path[{len(times) - 1}].t"))
    return found


_AT = re.compile(r"^(.*?)(?: - at `\$\.?(.*)`)?$")
_UNKNOWN = re.compile(r"unknown field `([^`]*)`")


def _split(message: str) -> tuple[str, str]:
    """msgspec's "Expected ... - at `$.a[0].b`" -> ("a[0].b", "expected ..."); an
    unknown field's key is its own name under the path."""
    found = _AT.match(message)
    assert found is not None  # the pattern matches any text
    reason, key = found.group(1), found.group(2) or ""
    unknown = _UNKNOWN.search(reason)
    if unknown:
        return (f"{key}.{unknown.group(1)}" if key else unknown.group(1)), "unknown key"
    reason = reason.replace("`", "")
    return key, reason[:1].lower() + reason[1:]


def _where(source: str, text: str, key: str) -> str:
    """'FILE, line N, key K: ' for the line where `key` (msgspec path) is written."""
    if not key:
        return f"{source}: "
    line = locate(text, key)
    at = f", line {line}" if line else ""
    return f"{source}{at}, key '{key}': "


_STEP = re.compile(r"([A-Za-z_][\w-]*)(?:\[(\d+)\])?")


def locate(text: str, key: str) -> int | None:
    """The 1-based line where a msgspec path such as `person[1].path[2].t` is written.

    Walks the file's lines: `[[person]]` headers count array-of-tables
    entries, `name = [` opens an array whose `{...}` items are counted, and
    the last step is the first `name =` inside the region found so far.
    Best effort: None when the file is laid out in a way this does not follow.
    """
    lines = text.splitlines()
    start, end = 0, len(lines)
    steps = _STEP.findall(key)
    for depth, (name, index) in enumerate(steps):
        last = depth == len(steps) - 1
        if index:
            region = _table_entry(lines, start, end, name, int(index)) or \
                _inline_item(lines, start, end, name, int(index))
            if region is None:
                return None
            start, end = region
            if last:
                return start + 1
            continue
        for n in range(start, end):
            if re.match(rf"\s*{re.escape(name)}\s*=", lines[n]) or \
                    re.search(rf"[{{,]\s*{re.escape(name)}\s*=", lines[n]):
                if last:
                    return n + 1
                start = n
                break
        else:
            return None
    return start + 1 if steps else None


def _table_entry(lines: list[str], start: int, end: int, name: str,
                 index: int) -> tuple[int, int] | None:
    """Lines of the `index`-th `[[name]]` entry."""
    heads = [n for n in range(start, end) if lines[n].strip() == f"[[{name}]]"]
    if index >= len(heads):
        return None
    head = heads[index]
    stop = next((n for n in range(head + 1, end) if lines[n].lstrip().startswith("[")), end)
    return head, stop


def _inline_item(lines: list[str], start: int, end: int, name: str,
                 index: int) -> tuple[int, int] | None:
    """The line of the `index`-th `{...}` item of the array `name = [...]`."""
    opened = next((n for n in range(start, end)
                   if re.match(rf"\s*{re.escape(name)}\s*=\s*\[", lines[n])), None)
    if opened is None:
        return None
    seen = 0
    for n in range(opened, end):
        for _ in re.finditer(r"\{", lines[n]):
            if seen == index:
                return n, n + 1
            seen += 1
        if "]" in lines[n].split("#")[0] and n > opened and "{" not in lines[n]:
            break
    return None
