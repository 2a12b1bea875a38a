"""Eye styles as data (services/eyes/styles.py): the built-in file, user files, errors."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.eyes import styles, wire
from buddybot.eyes.settings import EyeRendererSettings
from buddybot.runtime.errors import ConfigError
from buddybot.tools.testing import buddybot_argv


def write(tmp_path: Path, data: Any) -> Path:
    path = tmp_path / "styles.json"
    path.write_text(json.dumps(data))
    return path


def test_the_built_in_file_loads_with_both_styles_and_glow_is_the_default() -> None:
    library = styles.load()
    assert {"glow", "eyeball"} <= set(library.names)
    assert library.get("glow").kind == "glow" and library.get("eyeball").kind == "eyeball"
    assert EyeRendererSettings().style == "glow"


def test_every_expression_has_its_own_pose_in_each_built_in_style() -> None:
    """Named in the file itself (not only inherited from the base), and no two alike."""
    specs = styles.builtin_specs()
    assert tuple(a.name.split("_", 1)[1] for a in m.ExpressionAction) == styles.EXPRESSIONS
    for name, style in styles.load().styles.items():
        assert set(specs[name]["poses"]) == set(styles.EXPRESSIONS), name
        poses = [msgspec.to_builtins(style.poses[e]) for e in styles.EXPRESSIONS]
        for i, a in enumerate(poses):
            for b in poses[i + 1:]:
                assert a != b, (name, a)


def test_the_key_poses_say_what_the_issue_asks_for() -> None:
    for style in styles.load().styles.values():
        p = style.poses
        assert p["LOVE"].shape == "heart" and p["STAR"].shape == "star"
        assert p["GRIN"].bottom_lid_curve > 50                  # happy crescent
        assert p["SAD"].top_lid_angle > 0                       # outer corners down
        assert p["SLEEPY"].top_lid >= 30                        # drowsy half lids
        assert p["SLEEP"].breathe > 0                           # slow breathing glow
        assert p["AWAKE"].shape == "eye" and p["AWAKE"].top_lid == 0


@pytest.mark.parametrize(("pose", "message"), [
    ({"top_lid": 101}, "styles.glow.poses.GRIN.top_lid: expected <= 100"),
    ({"top_lid": -1}, "styles.glow.poses.GRIN.top_lid: expected >= 0"),
    ({"top_lid_angle": 60}, "styles.glow.poses.GRIN.top_lid_angle: expected <= 45"),
    ({"width": "wide"}, "styles.glow.poses.GRIN.width: expected `float`, got `str`"),
    ({"color": "red"}, "styles.glow.poses.GRIN.color"),
    ({"shape": "square"}, "styles.glow.poses.GRIN.shape"),
    ({"wiggle": 3}, "styles.glow.poses.GRIN: object contains unknown field `wiggle`"),
])
def test_a_bad_pose_value_is_refused_naming_its_key(tmp_path: Path, pose: dict[str, Any],
                                                     message: str) -> None:
    path = write(tmp_path, {"styles": {"glow": {"poses": {"GRIN": pose}}}})
    with pytest.raises(ConfigError) as refused:
        styles.load(path)
    assert str(refused.value).startswith(f"{path}: {message}"), str(refused.value)


@pytest.mark.parametrize(("data", "message"), [
    ({"styles": {"glow": {"poses": {"GIGGLE": {}}}}},
     "styles.glow.poses.GIGGLE: unknown expression (known: AWAKE, SLEEP"),
    ({"styles": {"glow": {"reach": 150}}}, "styles.glow.reach: expected <= 100"),
    ({"styles": {"glow": {"kind": "neon"}}}, "styles.glow.kind"),
    ({"styles": {"glow": {"blinky": True}}}, "styles.glow: object contains unknown field"),
    ({"styles": {"glow": {"base": {"glow": 200}}}}, "styles.glow.base.glow: expected <= 100"),
    ({"styles": {"mine": {"color": "#ffffff"}}}, "styles.mine: missing kind"),
    ({"styles": {"mine": {"extends": "nope"}}}, "styles.mine.extends = 'nope': no such style"),
    ({"styles": {"a": {"extends": "b"}, "b": {"extends": "a"}}}, "styles.a.extends: a loop"),
    ({"styles": {"bad name": {"extends": "glow"}}}, "styles.bad name: a style name is"),
    ({"looks": {}}, "a style file is an object with one key"),
    ({"styles": []}, "styles: expected an object"),
])
def test_a_bad_style_file_is_refused_naming_the_key(tmp_path: Path, data: Any,
                                                     message: str) -> None:
    path = write(tmp_path, data)
    with pytest.raises(ConfigError) as refused:
        styles.load(path)
    assert message in str(refused.value) and str(path) in str(refused.value)


def test_not_json_and_no_file_are_config_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    with pytest.raises(ConfigError, match="not valid JSON"):
        styles.load(bad)
    with pytest.raises(ConfigError, match="cannot read style file"):
        styles.load(tmp_path / "missing.json")


def test_a_user_file_adds_a_style_and_changes_a_built_in_one(tmp_path: Path) -> None:
    path = write(tmp_path, {"styles": {
        "ember": {"extends": "glow", "color": "#ff8a1f", "base": {"glow": 90},
                  "poses": {"GRIN": {"bottom_lid": 45}}},
        "eyeball": {"poses": {"SAD": {"top_lid_angle": 30}}},
    }})
    builtin = styles.load()
    library = styles.load(path)
    assert set(library.names) == set(builtin.names) | {"ember"}
    ember, glow = library.get("ember"), builtin.get("glow")
    assert ember.kind == "glow" and ember.color == "#ff8a1f"
    assert ember.poses["GRIN"].bottom_lid == 45
    assert ember.poses["GRIN"].bottom_lid_curve == glow.poses["GRIN"].bottom_lid_curve
    assert all(ember.poses[e].glow == 90 for e in styles.EXPRESSIONS)   # its base: all poses
    assert ember.poses["LOVE"].shape == "heart"                          # inherited
    # The built-in eyeball changed in one value, everything else kept.
    eyeball = library.get("eyeball")
    assert eyeball.poses["SAD"].top_lid_angle == 30
    assert eyeball.poses["GRIN"] == builtin.get("eyeball").poses["GRIN"]
    assert eyeball.background == builtin.get("eyeball").background
    assert library.get("glow") == glow


def test_a_complete_new_style_needs_no_parent(tmp_path: Path) -> None:
    glow = styles.load().get("glow")
    fields = {k: getattr(glow, k) for k in styles.STYLE_FIELDS}
    base = msgspec.to_builtins(glow.poses["AWAKE"])
    path = write(tmp_path, {"styles": {"plain": {**fields, "base": base}}})
    plain = styles.load(path).get("plain")
    assert all(plain.poses[e] == glow.poses["AWAKE"] for e in styles.EXPRESSIONS)
    del base["shape"]
    write(tmp_path, {"styles": {"plain": {**fields, "base": base}}})
    with pytest.raises(ConfigError, match=r"styles\.plain\.poses\.AWAKE: missing shape"):
        styles.load(path)


def test_the_style_setting_must_name_a_known_style() -> None:
    library = styles.load()
    with pytest.raises(ConfigError) as refused:
        library.get("sparkly")
    text = str(refused.value)
    assert "eye_renderer.style = 'sparkly'" in text
    assert "known: eyeball, glow" in text


def test_the_hello_carries_the_whole_style() -> None:
    style = styles.load().get("glow")
    hello = wire.Hello(iris_color="#2f7fd0", max_yaw_deg=40.0, max_pitch_deg=30.0,
                       server_id="x", style=style)
    msg = json.loads(wire.encode("hello", hello))["msg"]
    assert msg["style"]["kind"] == "glow"
    assert set(msg["style"]["poses"]) == set(styles.EXPRESSIONS)
    assert msg["style"]["poses"]["LOVE"]["shape"] == "heart"


@pytest.mark.integration
def test_the_renderer_refuses_to_start_with_an_unknown_style_or_a_bad_file(
        tmp_path: Path) -> None:
    """Exit status 2 (not restarted) with the key in the message, before serving."""
    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(buddybot_argv("run", "eye-renderer", "--no-browser", "--port", "0",
                                            "--connect", "tcp/127.0.0.1:1", *args),
                              capture_output=True, text=True, timeout=60)

    unknown = run("--style", "sparkly")
    assert unknown.returncode == 2, unknown.stderr
    assert "eye_renderer.style = 'sparkly': no such style (known: eyeball, glow)" in unknown.stderr
    path = write(tmp_path, {"styles": {"glow": {"poses": {"GRIN": {"top_lid": 101}}}}})
    bad = run("--style-file", str(path))
    assert bad.returncode == 2, bad.stderr
    assert "styles.glow.poses.GRIN.top_lid: expected <= 100" in bad.stderr
    assert "Traceback" not in bad.stderr + unknown.stderr
