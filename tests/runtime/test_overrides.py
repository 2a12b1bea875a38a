"""Every setting, walked: from TOML, from the command line, and into the running service.

Nothing here lists fields by hand. The walk starts at `Config`'s tables
and the services in `registry.SERVICES`, derives a valid non-default value
and an out-of-range value for each field from its type and `msgspec.Meta`
bounds, and checks that (a) the config file gives it back, (b) a value
out of range is refused naming the key, (c) every option bound to a field
reaches the merged struct (0 and "" included) or is refused naming the
flag, and (d) each service's `run()` starts from that merged struct. A new
field or flag is covered the day it is added.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import msgspec
import msgspec.inspect as mi
import pytest

from buddybot.runtime import overrides
from buddybot.runtime.config import Config, parse_config
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.registry import SERVICES
from buddybot.runtime.service import ServiceContext, add_common_arguments, resolve

# --- the walk -------------------------------------------------------------------------


def _plain(t: mi.Type) -> mi.Type:
    """The type without its Meta wrapper."""
    return t.type if isinstance(t, mi.Metadata) else t


def _examples(t: mi.Type) -> list[Any]:
    return list((t.extra_json_schema or {}).get("examples", [])) if isinstance(
        t, mi.Metadata) else []


def _optional(t: mi.Type) -> mi.Type | None:
    """X for `X | None`, else None."""
    t = _plain(t)
    if isinstance(t, mi.UnionType):
        rest = [u for u in t.types if not isinstance(u, mi.NoneType)]
        if len(rest) == 1 and len(t.types) == 2:
            return rest[0]
    return None


def struct_fields(cls: type, path: tuple[str, ...]) -> Iterator[tuple[tuple[str, ...], mi.Field]]:
    """(path, field) of every leaf field under a struct, nested structs walked."""
    info = mi.type_info(cls)
    assert isinstance(info, mi.StructType)
    for field in info.fields:
        inner = _plain(field.type)
        if isinstance(inner, mi.StructType):
            yield from struct_fields(inner.cls, (*path, field.name))
        else:
            yield (*path, field.name), field


def config_fields() -> list[tuple[tuple[str, ...], mi.Field]]:
    """Every leaf field of every table of the config file."""
    found = []
    for table in mi.type_info(Config).fields:  # type: ignore[union-attr]
        inner = _plain(table.type)
        if isinstance(inner, mi.StructType):
            found.extend(struct_fields(inner.cls, (table.name,)))
    return found


FIELDS = config_fields()


def _default(field: mi.Field) -> Any:
    if field.default is not msgspec.NODEFAULT:
        return field.default
    if field.default_factory is not msgspec.NODEFAULT:
        return field.default_factory()
    return None


def _number_candidates(t: mi.IntType | mi.FloatType) -> list[float]:
    """In-range numbers, the bounds themselves first (where a bound is inclusive)."""
    lo = t.ge if t.ge is not None else (t.gt if t.gt is not None else None)
    hi = t.le if t.le is not None else (t.lt if t.lt is not None else None)
    step = 1 if isinstance(t, mi.IntType) else 0.5
    found: list[float] = []
    if t.ge is not None:
        found.append(t.ge)
    if t.gt is not None:
        found.append(t.gt + step if hi is None or t.gt + step < hi else (t.gt + hi) / 2)
    found += [7, 3, 1, 0.5, 2]
    if t.le is not None:
        found.append(t.le)
    if lo is not None and hi is not None:
        found += [lo + (hi - lo) * k for k in (0.5, 0.25, 0.75)]
    return found


def in_range(t: mi.IntType | mi.FloatType, x: float) -> bool:
    return ((t.ge is None or x >= t.ge) and (t.gt is None or x > t.gt)
            and (t.le is None or x <= t.le) and (t.lt is None or x < t.lt))


def sample(t: mi.Type, avoid: Any = None, *, nonzero: bool = False) -> Any:
    """A valid value of `t` other than `avoid` (and, with `nonzero`, other than 0/"")."""
    for example in _examples(t):
        if example != avoid:
            return example
    inner = _optional(t)
    if inner is not None:
        return sample(inner, avoid, nonzero=nonzero)
    t = _plain(t)
    if isinstance(t, mi.BoolType):
        return not avoid
    if isinstance(t, (mi.IntType, mi.FloatType)):
        kind = int if isinstance(t, mi.IntType) else float
        for x in _number_candidates(t):
            x = kind(x)
            if in_range(t, x) and x != avoid and not (nonzero and x == 0):
                return x
        raise AssertionError(f"no sample for {t}")
    if isinstance(t, mi.StrType):
        assert t.pattern is None, f"give a Meta example for the pattern {t.pattern}"
        for text in ("x7", "y8"):
            if text != avoid:
                return text
    if isinstance(t, mi.LiteralType):
        return next(v for v in t.values if v != avoid)
    if isinstance(t, mi.ListType):
        return [sample(t.item_type, nonzero=True)]
    if isinstance(t, mi.TupleType):
        return tuple(sample(item, nonzero=True) for item in t.item_types)
    if isinstance(t, mi.DictType):
        return {"k1": sample(t.value_type, nonzero=True)}
    raise AssertionError(f"no sample for {t}")


def outside(t: mi.Type) -> Any:
    """A value of the right type its Meta refuses, or None when nothing is refused."""
    inner = _optional(t)
    if inner is not None:
        return outside(inner)
    t = _plain(t)
    if isinstance(t, (mi.IntType, mi.FloatType)):
        kind = int if isinstance(t, mi.IntType) else float
        if t.gt is not None:
            return kind(t.gt)
        if t.ge is not None:
            return kind(t.ge - max(1, abs(t.ge)))
        if t.lt is not None:
            return kind(t.lt)
        if t.le is not None:
            return kind(t.le + max(1, abs(t.le)))
        return None
    if isinstance(t, mi.StrType):
        if t.min_length:
            return ""
        if t.max_length is not None:
            return "x" * (t.max_length + 1)
        if t.pattern is not None:
            return "no match"
        return None
    if isinstance(t, mi.ListType):
        bad = outside(t.item_type)
        return None if bad is None else [bad]
    if isinstance(t, mi.TupleType):
        for i, item in enumerate(t.item_types):
            bad = outside(item)
            if bad is not None:
                values = list(sample(t))
                values[i] = bad
                return values
    return None


def toml_for(path: tuple[str, ...], value: Any) -> str:
    data: Any = value
    for name in reversed(path):
        data = {name: data}
    return msgspec.toml.encode(data).decode()


def value_at(config: Config, path: tuple[str, ...]) -> Any:
    node: Any = config
    for name in path:
        node = getattr(node, name)
    return node


def ids(fields: list[tuple[tuple[str, ...], mi.Field]]) -> list[str]:
    return [".".join(path) for path, _ in fields]


# --- (a) and (b): the config file -----------------------------------------------------


@pytest.mark.parametrize(("path", "field"), FIELDS, ids=ids(FIELDS))
def test_every_field_can_be_set_from_toml(path: tuple[str, ...], field: mi.Field) -> None:
    value = sample(field.type, _default(field))
    config = parse_config(toml_for(path, value), "walk.toml")
    assert msgspec.to_builtins(value_at(config, path)) == msgspec.to_builtins(value)


BOUNDED = [(p, f) for p, f in FIELDS if outside(f.type) is not None]


@pytest.mark.parametrize(("path", "field"), BOUNDED, ids=ids(BOUNDED))
def test_a_value_out_of_range_is_refused_naming_the_key(
        path: tuple[str, ...], field: mi.Field) -> None:
    with pytest.raises(ConfigError, match=r"key '" + r"\.".join(path)):
        parse_config(toml_for(path, outside(field.type)), "walk.toml")


def _numbers(t: mi.Type) -> list[mi.Type]:
    """The number types a field is made of, outside lists and dicts."""
    inner = _optional(t)
    if inner is not None:
        return _numbers(inner)
    plain = _plain(t)
    if isinstance(plain, (mi.IntType, mi.FloatType)):
        return [t]
    if isinstance(plain, mi.TupleType):
        return [n for item in plain.item_types for n in _numbers(item)]
    return []


NUMERIC = [(p, f) for p, f in FIELDS if _numbers(f.type) and p[0] not in ("robot", "zenoh")]


@pytest.mark.parametrize(("path", "field"), NUMERIC, ids=ids(NUMERIC))
def test_every_number_has_a_range_and_a_description(
        path: tuple[str, ...], field: mi.Field) -> None:
    for t in _numbers(field.type):
        plain = _plain(t)
        assert isinstance(plain, (mi.IntType, mi.FloatType))
        assert (plain.ge, plain.gt) != (None, None), "no lower bound"
        assert (plain.le, plain.lt) != (None, None), "no upper bound"
        assert isinstance(t, mi.Metadata) and t.extra_json_schema.get("description"), \
            "no description (unit, why)"
        default = _default(field)
        if isinstance(default, (int, float)):
            assert in_range(plain, default)


# --- (c) and (d): the command line and the running service ----------------------------

STRUCTS = {_plain(f.type).cls.__name__: (f.name, _plain(f.type).cls)  # type: ignore[union-attr]
           for f in mi.type_info(Config).fields  # type: ignore[union-attr]
           if isinstance(_plain(f.type), mi.StructType)}


def service_parser(module: ModuleType) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    add_common_arguments(parser)
    module.add_arguments(parser)
    return parser


def bound(entry_name: str) -> list[tuple[str, overrides.Binding, argparse.Action]]:
    module = next(e for e in SERVICES if e.name == entry_name).load()
    return [(entry_name, b, a) for b, a in overrides.bound_options(service_parser(module))]


OPTIONS = [row for entry in SERVICES for row in bound(entry.name)]


def option_ids(rows: list[tuple[str, overrides.Binding, argparse.Action]]) -> list[str]:
    return [f"{name} {binding.flag}" for name, binding, _ in rows]


@pytest.fixture(autouse=True)
def _no_env_config(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("BUDDYBOT_CONFIG", raising=False)


def run_with(entry_name: str, tmp_path: Path, toml: str, argv: list[str]) -> tuple[
        ModuleType, ServiceContext]:
    """The service's module and the context `run()` gets, from a config and a command line."""
    module = next(e for e in SERVICES if e.name == entry_name).load()
    config = tmp_path / "walk.toml"
    config.write_text(toml)
    args = service_parser(module).parse_args(["--config", str(config), *argv])
    return module, resolve(args, entry_name)


def _field(binding: overrides.Binding) -> tuple[str, type, mi.Field]:
    table, cls = STRUCTS[binding.struct]
    return table, cls, overrides.field_info(cls, binding.field)


def cli_cases(action: argparse.Action, field: mi.Field, flag: str) -> list[tuple[list[str], Any]]:
    """(argv, the value the field must then hold) for one option."""
    t = field.type
    if isinstance(action, argparse.BooleanOptionalAction):
        return [([flag], True), (["--no-" + flag[2:]], False)]
    if action.nargs == 0:  # store_true / store_false
        return [([flag], action.const)]
    convert = getattr(action, "convert", None)
    if action.choices is not None:
        return [([flag, str(c)], convert(c) if convert else c) for c in action.choices]
    value = sample(t, _default(field))
    cases: list[tuple[list[str], Any]] = []
    if isinstance(value, list):
        cases.append(([a for item in value for a in (flag, str(item))], value))
    else:
        cases.append(([flag, str(value)], value))
        plain = _plain(_optional(t) or t)
        zero: Any = None
        if isinstance(plain, (mi.IntType, mi.FloatType)) and in_range(plain, 0):
            zero = 0
        elif isinstance(plain, mi.StrType) and not plain.min_length and plain.pattern is None:
            zero = ""
        if zero is not None:  # 0 and "" are values: never replaced by the config's
            cases.append(([flag, str(zero)], zero))
    return cases


@pytest.mark.parametrize(("service", "binding", "action"), OPTIONS, ids=option_ids(OPTIONS))
def test_every_flag_reaches_the_struct_the_service_runs_with(
        tmp_path: Path, service: str, binding: overrides.Binding, action: argparse.Action
) -> None:
    table, _cls, field = _field(binding)
    for argv, expected in cli_cases(action, field, action.option_strings[0]):
        # The config holds yet another valid value: falling back to it shows.
        config_value = sample(field.type, expected, nonzero=True)
        if isinstance(expected, bool):
            config_value = not expected
        elif isinstance(expected, list):
            config_value = sample(field.type) if not expected else []
        elif action.choices is not None:
            config_value = next(c for c in action.choices if c != expected)
        module, ctx = run_with(service, tmp_path, toml_for((table, field.name), config_value),
                               argv)
        settings = module.settings_from(ctx)
        if type(settings) is not _cls:  # a shared table's option (`[sim]`): merged alike
            settings = overrides.merge(ctx.config.section(_cls), ctx.args)
        got = getattr(settings, field.name)
        assert msgspec.to_builtins(got) == msgspec.to_builtins(expected), argv
        assert overrides.given(ctx.args, type(settings), field.name)


REFUSING = [row for row in OPTIONS
            if row[2].nargs != 0 and row[2].choices is None
            and outside(_field(row[1])[2].type) is not None]


@pytest.mark.parametrize(("service", "binding", "action"), REFUSING, ids=option_ids(REFUSING))
def test_a_flag_out_of_range_is_refused_naming_flag_range_and_value(
        tmp_path: Path, service: str, binding: overrides.Binding, action: argparse.Action
) -> None:
    table, _cls, field = _field(binding)
    bad = outside(field.type)
    items = bad if isinstance(bad, list) else [bad]
    argv = [a for item in items for a in (action.option_strings[0], str(item))]
    module, ctx = run_with(service, tmp_path, "", argv)
    with pytest.raises(ConfigError) as refused:
        if type(module.settings_from(ctx)) is not _cls:  # a shared table's option (`[sim]`)
            overrides.merge(ctx.config.section(_cls), ctx.args)
    text = str(refused.value)
    assert action.option_strings[0] in text and f"{table}.{field.name}" in text
    assert repr(items[0] if not isinstance(bad, list) else bad) in text
    assert "allowed" in text


@pytest.mark.parametrize("entry", SERVICES, ids=[e.name for e in SERVICES])
def test_no_service_option_bypasses_the_settings(entry: Any) -> None:
    """An option named like a settings field but declared with plain `add_argument`
    would be a second, unvalidated way in: every one must be bound."""
    parser = service_parser(entry.load())
    fields = {f.name for _table, cls in STRUCTS.values()
              for f in mi.type_info(cls).fields}  # type: ignore[union-attr]
    common = {"help", "connect", "robot", "config", "log_level"}
    for action in parser._actions:
        if overrides.binding_of(action.dest) is None and action.dest not in common:
            assert action.dest not in fields, f"{action.option_strings} is not bound"


class _Reached(Exception):
    pass


@pytest.mark.parametrize("entry", SERVICES, ids=[e.name for e in SERVICES])
def test_run_starts_from_the_merged_settings(tmp_path: Path, entry: Any,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """`run()` takes its settings from `settings_from` before anything else (no node
    is opened here): what the tests above check is what the service uses."""
    module, ctx = run_with(entry.name, tmp_path, "", [])
    seen: list[object] = []

    def spy(ctx_: ServiceContext) -> object:
        seen.append(ctx_)
        raise _Reached

    monkeypatch.setattr(module, "settings_from", spy)
    with pytest.raises(_Reached):
        module.run(ctx)
    assert seen == [ctx]


def test_the_logic_holds_the_merged_values(tmp_path: Path) -> None:
    """Where the logic is built by a pure function, it holds the merged values."""
    from buddybot.controller.behaviour import Behaviour
    from buddybot.radar import bridge, presence_service
    from buddybot.sim.options import world_from

    _m, ctx = run_with("radar-presence", tmp_path, "[radar_presence]\nrange_m = 3.0\n",
                       ["--exit-margin-m", "0", "--max-sensors", "4"])
    rules = presence_service.settings_from(ctx)
    tracker = presence_service.PresenceTracker(rules)
    assert (tracker.rules.range_m, tracker.rules.exit_margin_m, tracker.rules.max_sensors) == (
        3.0, 0.0, 4)

    _m, ctx = run_with("radar-bridge", tmp_path, "[radar_bridge]\nsensors = ['/dev/a']\n",
                       ["--sim", "--sim-speed", "2.5", "--device-id", "0"])
    opts = bridge.options_from(bridge.settings_from(ctx))
    # --sim leaves configured hardware alone: only the simulated sensor.
    assert (opts.urls, opts.sim, opts.device_id) == ([], True, 0)
    world, clock, _ = world_from(ctx)  # the simulated world it renders
    assert (world.scenario.name, clock.speed) == ("visit", 2.5)

    module, ctx = run_with("eyes", tmp_path, "", ["--unknown-distance-percent", "0"])
    assert module.build(ctx)[1] == 0.0

    module, ctx = run_with("controller", tmp_path, "", ["--camera", "side"])
    settings = module.settings_from(ctx)
    assert Behaviour(settings, 0.0).s is settings and settings.camera == "side"


def test_the_walk_covers_every_service_and_table() -> None:
    """Guards the walk itself: a service without options or a table without fields
    would make the tests above pass vacuously."""
    with_options = {name for name, _b, _a in OPTIONS}
    assert with_options == {e.name for e in SERVICES}
    tables = {path[0] for path, _f in FIELDS}
    assert {name for name, _cls in STRUCTS.values()} <= tables
    assert len(REFUSING) >= 20 and len(BOUNDED) >= 60
    assert all(not math.isnan(v) for _p, f in NUMERIC
               if isinstance(v := _default(f), float))


@pytest.mark.parametrize(("service", "binding", "action"), OPTIONS, ids=option_ids(OPTIONS))
def test_every_flag_says_what_it_sets_and_where_its_default_is(
        service: str, binding: overrides.Binding, action: argparse.Action) -> None:
    table, _cls, field = _field(binding)
    text = action.help or ""
    assert f"default from [{table}] {field.name}" in text
    # A Meta description (or an explicit help), not just the field's name.
    assert not text.startswith(field.name.replace("_", " ") + " (")


# --- the helper's own edges -----------------------------------------------------------


def test_nothing_given_leaves_the_config_object_itself() -> None:
    from buddybot.radar.settings import RadarBridgeSettings

    parser = argparse.ArgumentParser()
    overrides.settings_option(parser, "--sim", struct=RadarBridgeSettings, field="sim")
    overrides.settings_option(parser, "--sensor", struct=RadarBridgeSettings, field="sensors")
    cfg = RadarBridgeSettings(sim=True, sensors=["/dev/a"])
    # An absent store_true flag is None, not False: the config's true stays.
    assert overrides.merge(cfg, parser.parse_args([])) is cfg
    merged = overrides.merge(cfg, parser.parse_args(["--sensor", "a", "--sensor", "b"]))
    assert merged.sensors == ["a", "b"] and merged.sim is True and cfg.sensors == ["/dev/a"]


def test_a_field_bound_twice_is_a_programming_error() -> None:
    from buddybot.radar.settings import RadarBridgeSettings

    parser = argparse.ArgumentParser()
    group = parser.add_argument_group("radar")
    overrides.settings_option(parser, "--baudrate", struct=RadarBridgeSettings,
                              field="baudrate")
    with pytest.raises(ValueError, match="already bound to --baudrate"):
        overrides.settings_option(group, "--baud", struct=RadarBridgeSettings,
                                  field="baudrate")
    with pytest.raises(KeyError, match="no field"):
        overrides.settings_option(parser, "--x", struct=RadarBridgeSettings, field="nope")
