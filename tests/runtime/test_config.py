"""Config: typed TOML, errors naming key and file, exit status 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from buddybot.runtime.config import (
    ConfigError,
    config_dir,
    load_config,
    parse_config,
    resolve_path,
)

DESIGN_EXAMPLE = """
[robot]
id = "buddy"
[zenoh]
connect = ["tcp/127.0.0.1:7447"]
[radar_presence]
range_m = 2.0
[face_detector]
face_width_m = 0.15
fx = 600.0
fy = 600.0
[controller.camera_to_eyes]
translation_m = [0.0, 0.0, 0.0]
rpy_rad = [0.0, 0.0, 0.0]
[audio.sounds]
greeting = "sounds/greeting.wav"
farewell = "sounds/farewell.wav"
"""


def test_design_example_parses() -> None:
    config = parse_config(DESIGN_EXAMPLE, "example.toml")
    assert config.robot.id == "buddy"
    assert config.radar_presence.range_m == 2.0
    assert config.face_detector.fx == 600.0
    assert tuple(config.controller.camera_to_eyes.rpy_rad) == (0.0, 0.0, 0.0)
    assert config.audio.sounds["greeting"] == "sounds/greeting.wav"


def test_defaults_without_file(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("BUDDYBOT_CONFIG", raising=False)
    config = load_config(None)
    assert config.zenoh.connect == ["tcp/127.0.0.1:7447"]
    assert config.robot.id == "buddy"


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[radar_presence]\nrang_m = 2.0\n", "rang_m"),
        ("[radar_presence]\nrange_m = 'far'\n", "radar_presence.range_m"),
        ("[nonsense]\nx = 1\n", "nonsense"),
        ("[robot]\nid = 'a/b'\n", "robot.id"),
        ("[robot\nid = 1", "config.toml"),
        ("source = 'x'\n", "source"),
    ],
)
def test_bad_config_names_key_and_file(text: str, needle: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_config(text, "config.toml")
    assert needle in str(info.value)
    assert "config.toml" in str(info.value)


def test_env_variable_and_relative_paths(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "robot.toml"
    path.write_text("[robot]\nid = 'r7'\n")
    monkeypatch.setenv("BUDDYBOT_CONFIG", str(path))
    config = load_config(None)
    assert config.robot.id == "r7"
    assert resolve_path(config, "sounds/a.wav") == tmp_path / "sounds/a.wav"
    assert resolve_path(config, "/abs/a.wav") == Path("/abs/a.wav")
    assert config_dir(config) == tmp_path.resolve()
    # Typed as an option instead: relative to the working directory, like any command.
    assert resolve_path(config, "clip.mp4", from_command_line=True) == Path("clip.mp4")


def test_without_a_config_file_paths_stay_relative() -> None:
    config = parse_config(b"", "<defaults>")
    assert config_dir(config) is None
    assert resolve_path(config, "sounds/a.wav") == Path("sounds/a.wav")


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(str(tmp_path / "absent.toml"))


@pytest.mark.integration
def test_cli_exits_2_naming_key_and_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[radar_presence]\nrange_m = 'x'\n")
    result = subprocess.run(
        [sys.executable, "-m", "buddybot", "config", "--config", str(path)],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 2
    assert "radar_presence.range_m" in result.stderr and str(path) in result.stderr


def run_with_zenoh_file(tmp_path: Path, content: str) -> subprocess.CompletedProcess[str]:
    """`buddybot run eyes` with `[zenoh] config_file` holding `content` (next to the TOML)."""
    (tmp_path / "zenoh.json5").write_text(content)
    path = tmp_path / "robot.toml"
    path.write_text('[zenoh]\nconfig_file = "zenoh.json5"\n')
    return subprocess.run(
        [sys.executable, "-m", "buddybot", "run", "eyes", "--config", str(path)],
        capture_output=True, text=True, timeout=60,
    )


@pytest.mark.integration
def test_bad_zenoh_config_file_is_exit_2_naming_it(tmp_path: Path) -> None:
    """`[zenoh] config_file` resolves next to the TOML file; one Zenoh cannot parse stops
    the service with status 2 (the systemd units do not restart on it)."""
    result = run_with_zenoh_file(tmp_path, "{ this is: not json5 ")
    assert result.returncode == 2, result.stderr
    assert str(tmp_path / "zenoh.json5") in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.integration
@pytest.mark.parametrize(("content", "said"), [
    ("{a: " * 30_000 + "1" + "}" * 30_000, "nested deeper than 32 levels (line 1)"),
    ("// a comment\n{ a: " + "{ b: " * 100 + "1" + " }" * 101 + "\n", "(line 2)"),
    ("{ big: '" + "x" * (1 << 20) + "' }", "larger than 1 MiB"),
], ids=["deep", "deep-after-a-comment", "big"])
def test_a_zenoh_config_file_too_deep_or_too_big_is_exit_2_not_a_crash(
        tmp_path: Path, content: str, said: str) -> None:
    """Zenoh's JSON5 parser recurses per level: 30,000 levels overflowed the
    stack (SIGSEGV, exit 139, a crash loop under systemd). Bounded before it."""
    result = run_with_zenoh_file(tmp_path, content)
    assert result.returncode == 2, result.stderr
    assert str(tmp_path / "zenoh.json5") in result.stderr and said in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.splitlines()) <= 2


# --- [apps] ----------------------------------------------------------------------------


def test_apps_table_lists_app_specs() -> None:
    config = parse_config('[apps]\nrun = ["examples/apps/greeter.py", "mypkg.app:Hi", "wave"]\n')
    assert [s.kind for s in config.apps.specs()] == ["file", "module", "name"]
    assert parse_config("").apps.run == []


@pytest.mark.parametrize(("table", "why"), [
    ('run = "greeter.py"', "key 'apps.run': Expected array"),
    ('run = ["apps/greeter"]', "key 'apps': run: 'apps/greeter': an app file must end in .py"),
    ('run = [""]', "run: an empty app"),
    ('run = ["a/hi.py", "b/hi.py"]', "'a/hi.py' and 'b/hi.py' would both run as node 'hi'"),
    ('run = ["controller"]', "'controller' would run as node 'controller', the name of a service"),
    ("start = []", "key 'apps': unknown key start"),
])
def test_bad_apps_tables_are_refused_naming_the_key(table: str, why: str) -> None:
    with pytest.raises(ConfigError) as error:
        parse_config(f"[apps]\n{table}\n", "robot.toml")
    assert str(error.value).startswith("robot.toml: ")
    assert why in str(error.value)


def test_robot_ids_are_bounded_and_deep_files_refused() -> None:
    assert parse_config(f'[robot]\nid = "{"r" * 64}"\n').robot.id == "r" * 64
    with pytest.raises(ConfigError, match=r"is not a valid id \(1-64 letters") as err:
        parse_config(f'[robot]\nid = "{"r" * 5000}"\n', "robot.toml")
    assert len(str(err.value)) < 200
    with pytest.raises(ConfigError, match=r"robot\.toml: not valid TOML: nested deeper"):
        parse_config("[robot]\nid = " + "[" * 5000 + "]" * 5000 + "\n", "robot.toml")
