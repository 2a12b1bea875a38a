"""Generate the `buddybot_interfaces` ROS 2 package from the message contract.

The robot's own messages (no standard ROS type carries them) become
`.msg`/`.srv`/`.action` files that a ROS 2 workspace builds as they are
(`colcon build`). They are generated from the msgspec structs, the one
source of truth, and checked in under `ros2/buddybot_interfaces/`; a test
regenerates them and fails when the checked-in copy has drifted (as
`buddybot schemas --check` does for the JSON Schemas). Write them with
`python -m buddybot.ros2.interfaces [--check] [OUT]`.

Mapping (docs/ros2.md): bounded integers take the smallest ROS integer that
holds their range, integer enums are `uint8` with one constant per member,
floats `float64` (lossless), bounded strings and lists ROS bounded ones, an
optional scalar a sequence of at most one (`T[<=1]`, empty: none), an
optional list its list (empty: none). Units and ranges go into comments.
"""

from __future__ import annotations

import enum
import inspect
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
from msgspec import inspect as mi

from buddybot.contract import messages as m
from buddybot.contract import schemas

PACKAGE = "buddybot_interfaces"
ROOT = Path(__file__).resolve().parents[2] / "ros2" / PACKAGE
"""Where the checked-in package lives (in the source tree, not the wheel)."""

MESSAGES: tuple[type[m.Message], ...] = (
    m.LD2410TargetDataFrame, m.LD2410TargetDataFrameArray, m.PresenceDetection,
    m.ScreenExpression, m.EyeControl, m.EyesDirection, m.PupilControl, m.EyeLidControl,
)
"""Contract messages with no standard ROS type, in the order of docs/design.md."""


@dataclass(frozen=True)
class Part:
    """A section of a `.srv`/`.action`: the fields `fields` (all when None) of `source`."""

    source: type[m.Message]
    fields: tuple[str, ...] | None = None


SERVICES: dict[str, tuple[Part, Part]] = {
    "PlayAudioFile": (Part(m.PlayAudioFile), Part(m.TriggerReply)),
}
"""Service name -> (request, response)."""

ACTIONS: dict[str, tuple[Part, Part, Part]] = {
    "PlaySound": (Part(m.PlaySound), Part(m.PlaySoundStatus, ("state", "message")),
                  Part(m.PlaySoundStatus, ("state", "progress"))),
}
"""Action name -> (goal, result, feedback): the result is the goal's last
status, the feedback its progress."""

HEADER = "# Generated from buddybot's message contract (services/contract/messages.py)\n" \
         "# by buddybot.ros2.interfaces: do not edit.\n"


class InterfaceError(ValueError):
    """A contract field that has no faithful ROS 2 type."""


def _unwrap(t: Any) -> tuple[Any, str]:
    """The type under a `Metadata` wrapper and its description ('' without one)."""
    if isinstance(t, mi.Metadata):
        return t.type, str((t.extra_json_schema or {}).get("description", ""))
    return t, ""


def _int_type(t: mi.IntType) -> str:
    lo = t.ge if t.ge is not None else (t.gt + 1 if t.gt is not None else None)
    hi = t.le if t.le is not None else (t.lt - 1 if t.lt is not None else None)
    if lo is not None and lo >= 0:
        for bits in (8, 16, 32):
            if hi is not None and hi < 2 ** bits:
                return f"uint{bits}"
        return "uint64"
    for bits in (8, 16, 32):
        if lo is not None and hi is not None and -(2 ** (bits - 1)) <= lo and hi < 2 ** (bits - 1):
            return f"int{bits}"
    return "int64"


def _range(t: Any) -> str:
    parts = []
    for name, sign in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
        value = getattr(t, name, None)
        if value is not None:
            parts.append(f"{sign} {value}")
    return ", ".join(parts)


@dataclass
class Field:
    ros_type: str
    comment: str
    enum: type[enum.IntEnum] | None = None


def _scalar(t: Any, where: str) -> Field:
    """ROS type of a non-optional, non-list field type."""
    t, desc = _unwrap(t)
    notes = [desc] if desc else []
    if isinstance(t, mi.EnumType) and issubclass(t.cls, enum.IntEnum):
        if max(t.cls) > 255 or min(t.cls) < 0:
            raise InterfaceError(f"{where}: enum {t.cls.__name__} does not fit uint8")
        return Field("uint8", f"{t.cls.__name__}: one of the constants above", t.cls)
    if isinstance(t, mi.IntType):
        rng = _range(t)
        return Field(_int_type(t), "; ".join([*([rng] if rng else []), *notes]))
    if isinstance(t, mi.FloatType):
        rng = _range(t)
        return Field("float64", "; ".join([*([rng] if rng else []), *notes]))
    if isinstance(t, mi.BoolType):
        return Field("bool", "; ".join(notes))
    if isinstance(t, mi.StrType):
        bound = f"<={t.max_length}" if t.max_length is not None else ""
        extra = [f"min length {t.min_length}"] if t.min_length else []
        return Field(f"string{bound}", "; ".join([*extra, *notes]))
    if isinstance(t, mi.LiteralType) and all(isinstance(v, str) for v in t.values):
        values = ", ".join(str(v) for v in t.values)
        return Field("string", f"one of {values}")
    if isinstance(t, mi.BytesType):
        return Field("uint8[]", "; ".join(notes))
    if isinstance(t, mi.StructType) and issubclass(t.cls, m.Message):
        return Field(t.cls.__name__, "; ".join(notes))
    raise InterfaceError(f"{where}: no ROS 2 type for {t!r}")


def _list(t: mi.ListType, where: str) -> Field:
    item = _scalar(t.item_type, where)
    if item.ros_type.endswith("]"):
        raise InterfaceError(f"{where}: a list of lists has no ROS 2 type")
    bound = f"<={t.max_length}" if t.max_length is not None else ""
    return Field(f"{item.ros_type}[{bound}]", f"each {item.comment}" if item.comment else "",
                 item.enum)


def ros_field(t: Any, where: str) -> Field:
    """The ROS 2 field of one contract field type."""
    t, desc = _unwrap(t)
    if isinstance(t, mi.UnionType):
        rest = [x for x in t.types if not isinstance(x, mi.NoneType)]
        if len(rest) != 1 or len(t.types) != 2:
            raise InterfaceError(f"{where}: only `X | None` unions have a ROS 2 type")
        inner, _ = _unwrap(rest[0])
        if isinstance(inner, mi.ListType):
            field = _list(inner, where)
            return Field(field.ros_type, _join(field.comment, desc, "empty: none"), field.enum)
        field = _scalar(rest[0], where)
        return Field(f"{field.ros_type}[<=1]", _join(field.comment, desc, "empty: none"),
                     field.enum)
    if isinstance(t, mi.ListType):
        field = _list(t, where)
        return Field(field.ros_type, _join(field.comment, desc), field.enum)
    field = _scalar(t, where)
    return Field(field.ros_type, _join(field.comment, desc), field.enum)


def _join(*notes: str) -> str:
    seen: list[str] = []
    for note in notes:
        if note and note not in seen:
            seen.append(note)
    return "; ".join(seen)


def section(part: Part) -> str:
    """The `.msg` text of `part`: its enums' constants, then its fields."""
    info = mi.type_info(part.source)
    assert isinstance(info, mi.StructType)
    wanted = part.fields if part.fields is not None else tuple(f.name for f in info.fields)
    by_name = {f.name: f for f in info.fields}
    unknown = [name for name in wanted if name not in by_name]
    if unknown:
        raise InterfaceError(f"{part.source.__name__} has no field {', '.join(unknown)}")
    fields = [(name, ros_field(by_name[name].type, f"{part.source.__name__}.{name}"))
              for name in wanted]
    lines: list[str] = []
    constants: dict[str, str] = {}
    for name, field in fields:
        if field.enum is None:
            continue
        lines.append(f"# {field.enum.__name__} (field {name})")
        for member in field.enum:
            if constants.setdefault(member.name, name) != name:
                raise InterfaceError(f"{part.source.__name__}: constant {member.name} of "
                                     f"{name} clashes with {constants[member.name]}'s")
            lines.append(f"uint8 {member.name}={member.value}")
    if lines:
        lines.append("")
    for name, field in fields:
        lines.append(f"{field.ros_type} {name}" + (f"  # {field.comment}" if field.comment
                                                   else ""))
    return "\n".join(lines) + "\n"


def _doc(cls: type[m.Message]) -> str:
    text = inspect.cleandoc(cls.__doc__ or "")
    if not text or text == (msgspec.Struct.__doc__ or "").strip():
        return ""
    return "".join(f"# {line}".rstrip() + "\n" for line in text.splitlines()) + "\n"


def _package_xml() -> str:
    return f"""<?xml version="1.0"?>
<?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
<!-- Generated by buddybot.ros2.interfaces: do not edit. -->
<package format="3">
  <name>{PACKAGE}</name>
  <version>0.1.0</version>
  <description>BuddyBot's own message, service and action types (radar frames,
    presence, eye expression and gaze, lids, pupils, sounds), generated from its
    message contract.</description>
  <maintainer email="buddybot@example.invalid">BuddyBot</maintainer>
  <license>Apache-2.0</license>

  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>

  <export>
    <build_type>ament_cmake</build_type>
  </export>
</package>
"""


def _cmakelists(names: list[str]) -> str:
    listed = "".join(f'  "{name}"\n' for name in names)
    return f"""# Generated by buddybot.ros2.interfaces: do not edit.
cmake_minimum_required(VERSION 3.8)
project({PACKAGE})

find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)

rosidl_generate_interfaces(${{PROJECT_NAME}}
{listed})

ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""


def generate() -> dict[str, str]:
    """File name (relative to the package folder) -> content."""
    files: dict[str, str] = {}
    for cls in MESSAGES:
        files[f"msg/{cls.__name__}.msg"] = HEADER + _doc(cls) + section(Part(cls))
    for name, (request, response) in SERVICES.items():
        files[f"srv/{name}.srv"] = HEADER + section(request) + "---\n" + section(response)
    for name, (goal, result, feedback) in ACTIONS.items():
        files[f"action/{name}.action"] = (HEADER + "# Goal\n" + section(goal) + "---\n# Result\n"
                                          + section(result) + "---\n# Feedback\n"
                                          + section(feedback))
    files["CMakeLists.txt"] = _cmakelists(sorted(files))
    files["package.xml"] = _package_xml()
    return files


def drift(out: Path = ROOT) -> list[str]:
    """Names of files that are missing, stale, or no longer generated."""
    return schemas.stale_files(out, generate())


def write(out: Path = ROOT) -> list[Path]:
    return schemas.write_files(out, generate())


def main(argv: list[str]) -> int:
    """`python -m buddybot.ros2.interfaces [--check] [OUT]`."""
    check = "--check" in argv
    rest = [a for a in argv if a != "--check"]
    out = Path(rest[0]) if rest else ROOT
    if check:
        stale = drift(out)
        for name in stale:
            print(f"out of date: {out / name}", file=sys.stderr)
        return 1 if stale else 0
    for path in write(out):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
