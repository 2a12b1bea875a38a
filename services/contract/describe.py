"""Turn any BuddyBot sample into one readable line (for `echo` and zenoh-cli).

The catalogue decides the type from the key; a payload that does not
decode is shown as such rather than hidden, because a person probing the
robot wants to see bad traffic too.

Enums travel as integers (msgspec IntEnum) but people read and type names:
`summarize` shows `"EYE_SLEEP"` (numbers with `names=False`), and
`enum_values` turns names typed by a person back into numbers. Both walk
the message type (msgspec.inspect), so nested and optional fields work too.
"""

from __future__ import annotations

import enum
import json
from functools import cache
from typing import Any

import msgspec
import msgspec.inspect as mi

from buddybot.contract import keys
from buddybot.contract import messages as m


def summarize(msg: m.Message, *, names: bool = True) -> str:
    """JSON for control messages (enum members by name unless `names=False`);
    a one-line summary for images.

    The image summary is built by a JSON encoder, never by string
    formatting: `frame_id` is free text from the wire, and a quote,
    backslash or newline in it must not turn `echo` output into invalid JSON.
    """
    if isinstance(msg, m.Image):
        return json.dumps({
            "type": "Image", "stamp_ns": msg.stamp_ns, "frame_id": msg.frame_id,
            "width": msg.width, "height": msg.height, "encoding": msg.encoding,
            "data": f"<{len(msg.data)} bytes>",
        })
    if names and _has_enum(type(msg)):
        return msgspec.json.encode(_named(msg)).decode()
    return msgspec.json.encode(msg).decode()


def describe(key: str, payload: bytes, *, names: bool = True) -> str:
    """Decode a payload published on `key` (absolute) and summarize it."""
    entry = keys.lookup_absolute(key)
    if isinstance(entry, keys.Topic):
        try:
            return summarize(entry.codec.decode(payload, entry.type), names=names)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            return f"<malformed {entry.type.__name__}: {exc}; {len(payload)} bytes>"
    if isinstance(entry, keys.Service):
        for msg_type in (entry.request, entry.reply):
            try:
                return summarize(entry.codec.decode(payload, msg_type), names=names)
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue
    try:
        return payload.decode("utf-8")
    except UnicodeDecodeError:
        return f"<{len(payload)} bytes>"


# --- enum names <-> numbers -------------------------------------------------------


def _named(value: Any) -> Any:
    """Builtins of a message with every enum member replaced by its name."""
    if isinstance(value, enum.Enum):
        return value.name
    if isinstance(value, msgspec.Struct):
        return {f.encode_name: _named(getattr(value, f.name))
                for f in msgspec.structs.fields(value)}
    if isinstance(value, (list, tuple)):
        return [_named(v) for v in value]
    if isinstance(value, dict):
        return {k: _named(v) for k, v in value.items()}
    return msgspec.to_builtins(value)


@cache
def _has_enum(msg_type: type) -> bool:
    return _info_has_enum(mi.type_info(msg_type), set())


def _info_has_enum(info: mi.Type, seen: set[type]) -> bool:
    if isinstance(info, mi.EnumType):
        return True
    if isinstance(info, mi.StructType):
        if info.cls in seen:
            return False
        seen.add(info.cls)
        return any(_info_has_enum(f.type, seen) for f in info.fields)
    return any(_info_has_enum(child, seen) for child in _children(info))


def _children(info: mi.Type) -> list[mi.Type]:
    if isinstance(info, mi.Metadata):
        return [info.type]
    if isinstance(info, mi.UnionType):
        return list(info.types)
    if isinstance(info, (mi.ListType, mi.SetType, mi.FrozenSetType, mi.VarTupleType)):
        return [info.item_type]
    if isinstance(info, mi.DictType):
        return [info.value_type]
    return []


def enum_values(raw: Any, msg_type: type) -> Any:
    """`raw` (decoded JSON for `msg_type`) with enum member names replaced by
    their numbers; anything else is left for msgspec to validate. Raises
    ValueError naming the field and the valid names for an unknown name."""
    return _to_values(raw, mi.type_info(msg_type), "")


def _to_values(raw: Any, info: mi.Type, path: str) -> Any:
    if isinstance(info, mi.EnumType) and isinstance(raw, str):
        cls = info.cls
        if raw in cls.__members__:
            return cls.__members__[raw].value
        if any(isinstance(member.value, int) for member in cls):
            choices = ", ".join(cls.__members__)
            raise ValueError(f"{path or 'message'}: unknown {cls.__name__} {raw!r} "
                             f"(one of {choices})")
        return raw
    if isinstance(info, mi.StructType) and isinstance(raw, dict):
        fields = {f.encode_name: f.type for f in info.fields}
        return {k: _to_values(v, fields[k], _join(path, k)) if k in fields else v
                for k, v in raw.items()}
    if isinstance(info, (mi.ListType, mi.SetType, mi.FrozenSetType, mi.VarTupleType)) \
            and isinstance(raw, list):
        return [_to_values(v, info.item_type, f"{path}[{i}]") for i, v in enumerate(raw)]
    if isinstance(info, mi.DictType) and isinstance(raw, dict):
        return {k: _to_values(v, info.value_type, _join(path, str(k))) for k, v in raw.items()}
    if isinstance(info, mi.Metadata):
        return _to_values(raw, info.type, path)
    if isinstance(info, mi.UnionType):
        for option in info.types:
            if isinstance(option, (mi.EnumType, mi.StructType, mi.ListType, mi.Metadata)):
                try:
                    return _to_values(raw, option, path)
                except ValueError:
                    continue
    return raw


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


class MessageTextError(ValueError):
    """A message typed by a person (JSON text) that is not a valid message."""


def parse_message(topic_or_type: type[m.Message], text: str) -> m.Message:
    """Validate user JSON against a message type; fills a missing `stamp_ns`.

    Enum fields take a member's name (`"EYE_SLEEP"`) as well as its number.
    Raises MessageTextError naming the offending field.
    """
    try:
        raw = msgspec.json.decode(text or "{}")
    except msgspec.DecodeError as exc:
        raise MessageTextError(f"not valid JSON: {exc}") from None
    if not isinstance(raw, dict):
        raise MessageTextError(f"expected a JSON object for {topic_or_type.__name__}")
    if "stamp_ns" in topic_or_type.__struct_fields__ and "stamp_ns" not in raw:
        raw["stamp_ns"] = m.now_ns()
    try:
        raw = enum_values(raw, topic_or_type)
        return msgspec.convert(raw, topic_or_type)
    except (msgspec.ValidationError, ValueError) as exc:
        text = str(exc).replace("$.", "").replace("`$`", "message")
        raise MessageTextError(f"invalid {topic_or_type.__name__}: {text}") from None
