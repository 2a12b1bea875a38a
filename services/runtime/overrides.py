"""Command-line options bound to settings fields: declared once, merged once.

Every service option that overrides a config value is declared with
`settings_option`, which takes the option's type, choices, range and help
text from the settings struct itself (its annotation and `msgspec.Meta`),
so a default or a bound is written in exactly one place: the struct.
`merge` then applies the options that were given onto the struct the
config file produced, validating each value with the field's own
annotation (a value out of range is a `ConfigError` naming the flag, the
key, the allowed range and the value).

Why "given" means "not None": `args.x or cfg.x` would turn `--baudrate 0`
and `--device-id 0` into the config value. Every bound option defaults to
None, so 0, "" and False are values like any other.

The binding travels inside the option's `dest` (a string argparse stores
as is), so a parsed namespace alone says which fields were set from which
flag: this survives sub-parsers and `parents=`, and needs no global state.
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, TypeVar

import msgspec
import msgspec.inspect as mi

from buddybot.runtime.config import config_type
from buddybot.runtime.errors import ConfigError

S = TypeVar("S", bound=msgspec.Struct)

_PREFIX = "settings:"
_SEP = ":"


@dataclass(frozen=True)
class Binding:
    """One option bound to one field: what `merge` needs to apply and report it."""

    struct: str
    """The settings struct's class name."""
    field: str
    flag: str
    """The option's first spelling, used in error messages."""
    dest: str


def _dest(struct: type[msgspec.Struct], field: str, flag: str) -> str:
    return f"{_PREFIX}{struct.__name__}{_SEP}{field}{_SEP}{flag}"


def binding_of(dest: str) -> Binding | None:
    """The binding a namespace key stands for (None: an ordinary option)."""
    if not dest.startswith(_PREFIX):
        return None
    struct, field, flag = dest[len(_PREFIX):].split(_SEP, 2)
    return Binding(struct, field, flag, dest)


def bound_options(parser: argparse.ArgumentParser) -> list[tuple[Binding, argparse.Action]]:
    """Every settings option of a parser (used by tests that walk all of them)."""
    found = []
    for action in parser._actions:
        binding = binding_of(action.dest)
        if binding is not None:
            found.append((binding, action))
    return found


# --- what a field's annotation says ---------------------------------------------------


def _unwrap(t: mi.Type) -> tuple[mi.Type, str]:
    """A field's inspected type without its Meta wrapper, and its description."""
    description = ""
    if isinstance(t, mi.Metadata):
        description = str((t.extra_json_schema or {}).get("description", ""))
        t = t.type
    return t, description


def _not_none(t: mi.Type) -> mi.Type:
    """`X | None` -> X: None is never typed on a command line."""
    return _unwrap(_optional_member(t))[0]


def _optional_member(t: mi.Type) -> mi.Type:
    """The X of `X | None` with its Meta wrapper kept (else `t` itself)."""
    if isinstance(t, mi.UnionType):
        rest = [u for u in t.types if not isinstance(u, mi.NoneType)]
        if len(rest) == 1:
            return rest[0]
    return t


def _description(t: mi.Type) -> str:
    """The field's Meta description, also when the Meta sits inside `X | None`."""
    outer, text = _unwrap(t)
    return text or _unwrap(_optional_member(outer))[1]


@functools.cache
def _struct_info(struct: type[msgspec.Struct]) -> mi.StructType:
    """`msgspec.inspect` of a settings struct, once per process: inspecting evaluates
    every annotation, tens of ms for the whole config, and a service's parser asks
    for each of its options."""
    info = mi.type_info(struct)
    assert isinstance(info, mi.StructType)
    return info


def struct_fields(struct: type[msgspec.Struct]) -> tuple[mi.Field, ...]:
    """The inspected fields of a settings struct (worked out once, `_struct_info`)."""
    return _struct_info(struct).fields


@functools.cache
def _annotations(struct: type[msgspec.Struct]) -> dict[str, Any]:
    return {f.name: f.type for f in msgspec.structs.fields(struct)}


def annotation(struct: type[msgspec.Struct], field: str) -> Any:
    """The field's annotation, as `msgspec.convert` takes it (worked out once)."""
    return _annotations(struct)[field]


def field_info(struct: type[msgspec.Struct], field: str) -> mi.Field:
    """The inspected field (KeyError naming it when the struct has no such field)."""
    for f in _struct_info(struct).fields:
        if f.name == field:
            return f
    raise KeyError(f"{struct.__name__} has no field {field!r}")


def _num(x: float) -> str:
    """A bound as typed in a config file: 256000 not 2.56e+05, 0.5 not 0.500000."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else repr(float(x))


def describe_range(t: mi.Type) -> str:
    """The Meta bounds of a (possibly optional) type in words, or "" when unbounded."""
    t = _not_none(_unwrap(t)[0])
    parts: list[str] = []
    if isinstance(t, (mi.IntType, mi.FloatType)):
        lo = f">= {_num(t.ge)}" if t.ge is not None else (
            f"> {_num(t.gt)}" if t.gt is not None else "")
        hi = f"<= {_num(t.le)}" if t.le is not None else (
            f"< {_num(t.lt)}" if t.lt is not None else "")
        if t.ge is not None and t.le is not None:
            return f"{_num(t.ge)}..{_num(t.le)}"
        parts = [p for p in (lo, hi) if p]
    elif isinstance(t, (mi.StrType, mi.ListType)):
        unit = "characters" if isinstance(t, mi.StrType) else "items"
        if t.min_length and t.max_length is not None:
            parts.append(f"{t.min_length}..{t.max_length} {unit}")
        elif t.min_length:
            parts.append(f"at least {t.min_length} {unit}")
        elif t.max_length is not None:
            parts.append(f"at most {t.max_length} {unit}")
        if isinstance(t, mi.StrType) and t.pattern:
            parts.append(f"matching {t.pattern}")
    return " and ".join(parts)


def table_of(struct: type[msgspec.Struct]) -> str:
    """The config table a settings struct is read from (its class name when none)."""
    for f in _struct_info(config_type()).fields:
        t = _unwrap(f.type)[0]
        if isinstance(t, mi.StructType) and t.cls is struct:
            return str(f.name)
    return struct.__name__


# --- declaring options ---------------------------------------------------------------


class _Convert(argparse.Action):
    """Store `convert(value)`: choices are checked on the typed text, the field gets
    the converted value (e.g. `--eyes both` -> ["left", "right"])."""

    def __init__(self, *args: Any, convert: Callable[[Any], Any], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.convert = convert

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        setattr(namespace, self.dest, self.convert(values))


def settings_option(
    container: argparse.ArgumentParser | argparse._ArgumentGroup,
    *flags: str,
    struct: type[msgspec.Struct],
    field: str,
    help: str | None = None,
    metavar: str | None = None,
    choices: Iterable[Any] | None = None,
    convert: Callable[[Any], Any] | None = None,
    action: str | type[argparse.Action] | None = None,
) -> argparse.Action:
    """Declare an option that overrides `struct.field`; it is applied by `merge`.

    The type, choices (a Literal) and range come from the field; `help`
    replaces the field's description when the option means something more
    specific. Booleans: `action="store_true"` (default) sets True,
    `"store_false"` (a `--no-x` flag) sets False, and
    `argparse.BooleanOptionalAction` gives both `--x` and `--no-x`; a flag
    not given leaves the config's value either way. A `list[str]` field is a
    repeatable option whose values replace the config's list.
    """
    if not flags:
        raise ValueError("settings_option needs at least one flag")
    # One option per field: two would make the result depend on which one wins.
    for other in container._actions:
        bound = binding_of(other.dest)
        if bound is not None and (bound.struct, bound.field) == (struct.__name__, field):
            raise ValueError(f"{struct.__name__}.{field} is already bound to {bound.flag}")
    info = field_info(struct, field)
    description = _description(info.type)
    t = _not_none(_unwrap(info.type)[0])
    kwargs: dict[str, Any] = {"dest": _dest(struct, field, flags[0]), "default": None}
    text = (help or description or field.replace("_", " ")).rstrip(".")
    bounds = "" if choices is not None or isinstance(t, mi.LiteralType) else describe_range(
        info.type)
    default = info.default if info.default is not msgspec.NODEFAULT else (
        info.default_factory() if info.default_factory is not msgspec.NODEFAULT else None)
    shown = "unset" if default is None else "empty" if default in ("", []) else default
    notes = [bounds] if bounds else []
    notes.append(f"default from [{table_of(struct)}] {field}, else {shown}")
    kwargs["help"] = f"{text} ({'; '.join(notes)})".replace("%", "%%")
    if isinstance(t, mi.BoolType):
        kwargs["action"] = action or "store_true"
    else:
        item = t
        if convert is not None:  # one typed value, converted to the field's value
            kwargs["action"] = _Convert
            kwargs["convert"] = convert
        elif isinstance(t, mi.ListType):
            kwargs["action"] = action or "append"
            item = _not_none(_unwrap(t.item_type)[0])
        elif action is not None:
            kwargs["action"] = action
        if isinstance(item, mi.LiteralType) and choices is None:
            choices = item.values
        elif isinstance(item, mi.IntType):
            kwargs["type"] = int
        elif isinstance(item, mi.FloatType):
            kwargs["type"] = float
        if choices is not None:
            kwargs["choices"] = list(choices)
        else:
            kwargs["metavar"] = metavar or field.upper()
    return container.add_argument(*flags, **kwargs)


# --- applying them -------------------------------------------------------------------


def overrides(args: argparse.Namespace, struct: type[msgspec.Struct]
              ) -> dict[str, tuple[Binding, Any]]:
    """The fields of `struct` given on the command line: field -> (binding, value)."""
    found: dict[str, tuple[Binding, Any]] = {}
    for dest, value in vars(args).items():
        binding = binding_of(dest)
        if binding is not None and binding.struct == struct.__name__ and value is not None:
            found[binding.field] = (binding, value)
    return found


def given(args: argparse.Namespace, struct: type[msgspec.Struct], field: str) -> bool:
    """Whether `field` came from the command line (a relative path then means the
    working directory, not the config file's folder)."""
    return field in overrides(args, struct)


def _allowed(t: mi.Type) -> str:
    """What a field accepts, for an error: its own bounds, else its items' bounds."""
    bounds = describe_range(t)
    inner = _not_none(_unwrap(t)[0])
    if not bounds and isinstance(inner, mi.ListType):
        item = describe_range(inner.item_type)
        bounds = f"each {item}" if item else ""
    return bounds


def merge(settings: S, args: argparse.Namespace) -> S:
    """`settings` with every bound option that was given applied, each validated.

    Each value goes through `msgspec.convert` with the field's annotation,
    the same check the config file got, so the command line cannot reach
    the service with a value the file would have been refused for.
    """
    struct = type(settings)
    changes: dict[str, Any] = {}
    for field, (binding, value) in overrides(args, struct).items():
        try:
            changes[field] = msgspec.convert(value, annotation(struct, field))
        except msgspec.ValidationError as exc:
            bounds = _allowed(field_info(struct, field).type)
            allowed = f"allowed {bounds}" if bounds else str(exc)
            raise ConfigError(f"{binding.flag} {value!r}: {allowed} "
                              f"(key '{table_of(struct)}.{field}')") from None
    return msgspec.structs.replace(settings, **changes) if changes else settings

