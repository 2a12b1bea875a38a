"""Configuration: one TOML file, one table per service plus `[robot]` and `[zenoh]`.

The file is decoded straight into typed msgspec structs, so an unknown
key or a wrong type is found at start-up and reported with the key's
path and the file's name (`ConfigError`, exit status 2), never discovered
later as a silently ignored setting. Each service owns its table's
struct in its own `settings.py` and names it in `buddybot.runtime.registry`;
this module only assembles them, on first use (`Config`), so importing
the runtime imports no area.
"""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import msgspec

from buddybot.contract.keys import DEFAULT_ROBOT, ID_MAX, valid_robot_id
from buddybot.runtime import nesting, registry
from buddybot.runtime.appspec import AppSpec, parse_app_spec
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.limits import clip

CONFIG_ENV = "BUDDYBOT_CONFIG"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


class RobotSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    id: str = DEFAULT_ROBOT
    allow_duplicate_nodes: bool = False
    """A second process with a service's name on the same robot is refused at
    start (two controllers would cancel each other's greetings); true allows it."""


def _default_connect() -> list[str]:
    return [DEFAULT_ENDPOINT]


class ZenohSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """How services reach the router.

    `config_file` is an optional Zenoh JSON5 config (TLS, credentials) that
    the runtime starts from; `connect` still decides the endpoints.
    `router_config_file` is the file of the router `buddybot up` starts (the
    listen side: its certificate, access control); unset, the router gets
    `config_file` too, which then has to hold both sides. Splitting them lets
    the shipped `deploy/zenoh/router.json5` and `robot.json5` be used as is.
    """

    connect: list[str] = msgspec.field(default_factory=_default_connect)
    config_file: str | None = None
    router_config_file: str | None = None


class AppsSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[apps]`: the apps `buddybot up` starts and supervises like its services.

    `run` lists app specs (`examples/apps/greeter.py`, `mypkg.app:Greeter`, an
    installed app's name; docs/apps.md). Each is checked here, as text: a
    malformed spec, or two apps (or an app and a service) that would get the
    same node name, stop the robot at start-up with the key named. A
    relative FILE is relative to the config file's folder, like every path.
    """

    run: list[str] = msgspec.field(default_factory=list)

    def __post_init__(self) -> None:
        seen: dict[str, str] = {}
        for text in self.run:
            try:
                name = parse_app_spec(text).default_name
            except ValueError as exc:  # msgspec names the table
                raise ValueError(f"run: {exc}") from None
            if name in seen:
                raise ValueError(f"run: {seen[name]!r} and {text!r} would both run as node "
                                 f"{name!r}")
            if registry.service(name) is not None:
                raise ValueError(f"run: {text!r} would run as node {name!r}, the name of a "
                                 "service")
            seen[name] = text

    def specs(self) -> list[AppSpec]:
        return [parse_app_spec(text) for text in self.run]


S = TypeVar("S")


class ConfigBase(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """The tables every process shares; `Config` adds one per registered service."""

    robot: RobotSettings = msgspec.field(default_factory=RobotSettings)
    zenoh: ZenohSettings = msgspec.field(default_factory=ZenohSettings)
    apps: AppsSettings = msgspec.field(default_factory=AppsSettings)
    # Where the file came from (not a TOML key); relative paths in it resolve here.
    source: str | None = None

    def section(self, kind: type[S]) -> S:
        """The table whose struct is `kind`, typed (`config.section(CameraSettings)`)."""
        for name in self.__struct_fields__:
            value = getattr(self, name)
            if type(value) is kind:
                return value
        raise LookupError(f"no config table of type {kind.__name__}")

    if TYPE_CHECKING:  # service tables are added at run time (`config_type`)
        def __getattr__(self, name: str) -> Any: ...


@functools.cache
def config_type() -> type[ConfigBase]:
    """The full config struct: the shared tables plus every registered service's.

    Built once, on first use: this is where the areas' settings modules are
    imported (pure msgspec structs, nothing else).
    """
    fields: list[tuple[str, type[Any], Any]] = []
    for entry in registry.SERVICES:
        if entry.table is not None:
            kind = entry.settings_type()
            fields.append((entry.table, kind, msgspec.field(default_factory=kind)))
    assembled: type[ConfigBase] = msgspec.defstruct(  # type: ignore[assignment]
        "Config", fields, bases=(ConfigBase,), module=__name__,
        forbid_unknown_fields=True, kw_only=True,
    )
    return assembled


def __getattr__(name: str) -> Any:
    """`Config` (the assembled struct) is made when first asked for."""
    if name == "Config":
        return config_type()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


if TYPE_CHECKING:
    Config = ConfigBase


_AT = re.compile(r" - at `\$\.?(.*)`$")


def _readable(error: Exception) -> str:
    """msgspec's 'Expected `int`, got `str` - at `$.a.b`' -> '`a.b`: expected int, got str'."""
    text = str(error)
    found = _AT.search(text)
    where = found.group(1) if found else ""
    text = _AT.sub("", text)
    text = text.replace("Object contains unknown field", "unknown key")
    text = text.replace("`", "")
    if where:
        return f"key '{where}': {text}"
    return text


def default_config() -> ConfigBase:
    """Every table at its defaults (no config file)."""
    return config_type()()


def parse_config(data: bytes | str, source: str = "<config>") -> ConfigBase:
    """Decode TOML text into a validated Config, or raise ConfigError."""
    try:
        nesting.check_depth(data, toml=True)
        config = msgspec.toml.decode(data, type=config_type())
    except nesting.TooDeep as exc:
        raise ConfigError(f"{source}: not valid TOML: {exc}") from None
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise ConfigError(f"{source}: {_readable(exc)}") from None
    if config.source is not None:
        raise ConfigError(f"{source}: unknown key 'source'")
    if not valid_robot_id(config.robot.id):
        raise ConfigError(f"{source}: key 'robot.id': {clip(repr(config.robot.id), 80)} is not "
                          f"a valid id (1-{ID_MAX} letters, digits, '-', '_')")
    config.source = source
    return config


def config_path(explicit: str | None) -> Path | None:
    """`--config` wins, then $BUDDYBOT_CONFIG, else no file (all defaults)."""
    chosen = explicit or os.environ.get(CONFIG_ENV) or None
    return Path(chosen) if chosen else None


def load_config(explicit: str | None = None) -> ConfigBase:
    """Load the effective configuration file (or defaults when there is none)."""
    path = config_path(explicit)
    if path is None:
        return default_config()
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file: {exc.strerror}") from None
    return parse_config(data, str(path))


def config_dir(config: ConfigBase) -> Path | None:
    """The folder relative paths in the config start from (None without a config file).

    Written once so every service reads `sounds/a.wav` or `models/x.tflite` in
    robot.toml the same way, whatever its working directory (systemd, `up`).
    """
    if config.source is None or config.source.startswith("<"):
        return None
    return Path(config.source).resolve().parent


def resolve_path(config: ConfigBase, value: str, *, from_command_line: bool = False) -> Path:
    """A path from the config: absolute as is, relative to the config file's folder.

    `from_command_line`: the value was an option instead, and a relative path
    typed in a shell means the working directory, as for every other command.
    """
    if from_command_line:
        return Path(value)
    path = Path(value).expanduser()
    base = config_dir(config)
    if path.is_absolute() or base is None:
        return path
    return base / path


def to_toml_dict(config: ConfigBase) -> dict[str, object]:
    """The effective configuration as plain data (what `buddybot config` prints)."""
    data: dict[str, object] = msgspec.to_builtins(config)
    data.pop("source", None)
    return data
