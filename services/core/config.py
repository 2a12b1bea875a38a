"""Configuration: one TOML file, one table per service plus `[robot]` and `[zenoh]`.

The file is decoded straight into typed msgspec structs, so an unknown
key or a wrong type is found at start-up and reported with the key's
path and the file's name (`ConfigError`, exit status 2), never discovered
later as a silently ignored setting. Each service owns its table's
struct in its own `settings.py`; this module only assembles them.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import msgspec

from buddybot.audio.settings import AudioPlayerSettings, AudioSettings
from buddybot.camera.settings import CameraSettings, FaceDetectorSettings
from buddybot.controller.settings import ControllerSettings
from buddybot.core.errors import ConfigError
from buddybot.core.keys import DEFAULT_ROBOT, valid_robot_id
from buddybot.eyes.settings import EyeRendererSettings, EyesSettings
from buddybot.radar.settings import RadarBridgeSettings, RadarPresenceSettings

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
    """

    connect: list[str] = msgspec.field(default_factory=_default_connect)
    config_file: str | None = None


class Config(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    robot: RobotSettings = msgspec.field(default_factory=RobotSettings)
    zenoh: ZenohSettings = msgspec.field(default_factory=ZenohSettings)
    radar_bridge: RadarBridgeSettings = msgspec.field(default_factory=RadarBridgeSettings)
    radar_presence: RadarPresenceSettings = msgspec.field(default_factory=RadarPresenceSettings)
    camera: CameraSettings = msgspec.field(default_factory=CameraSettings)
    face_detector: FaceDetectorSettings = msgspec.field(default_factory=FaceDetectorSettings)
    controller: ControllerSettings = msgspec.field(default_factory=ControllerSettings)
    eyes: EyesSettings = msgspec.field(default_factory=EyesSettings)
    eye_renderer: EyeRendererSettings = msgspec.field(default_factory=EyeRendererSettings)
    audio: AudioSettings = msgspec.field(default_factory=AudioSettings)
    audio_player: AudioPlayerSettings = msgspec.field(default_factory=AudioPlayerSettings)
    # Where the file came from (not a TOML key); relative paths in it resolve here.
    source: str | None = None


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


def parse_config(data: bytes | str, source: str = "<config>") -> Config:
    """Decode TOML text into a validated Config, or raise ConfigError."""
    try:
        config = msgspec.toml.decode(data, type=Config)
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise ConfigError(f"{source}: {_readable(exc)}") from None
    if config.source is not None:
        raise ConfigError(f"{source}: unknown key 'source'")
    if not valid_robot_id(config.robot.id):
        raise ConfigError(f"{source}: key 'robot.id': {config.robot.id!r} is not a valid id")
    config.source = source
    return config


def config_path(explicit: str | None) -> Path | None:
    """`--config` wins, then $BUDDYBOT_CONFIG, else no file (all defaults)."""
    chosen = explicit or os.environ.get(CONFIG_ENV) or None
    return Path(chosen) if chosen else None


def load_config(explicit: str | None = None) -> Config:
    """Load the effective configuration file (or defaults when there is none)."""
    path = config_path(explicit)
    if path is None:
        return Config()
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file: {exc.strerror}") from None
    return parse_config(data, str(path))


def config_dir(config: Config) -> Path | None:
    """The folder relative paths in the config start from (None without a config file).

    Written once so every service reads `sounds/a.wav` or `models/x.tflite` in
    robot.toml the same way, whatever its working directory (systemd, `up`).
    """
    if config.source is None or config.source.startswith("<"):
        return None
    return Path(config.source).resolve().parent


def resolve_path(config: Config, value: str, *, from_command_line: bool = False) -> Path:
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


def to_toml_dict(config: Config) -> dict[str, object]:
    """The effective configuration as plain data (what `buddybot config` prints)."""
    data = msgspec.to_builtins(config)
    data.pop("source", None)
    return data
