"""Scenario files: the built-in ones run, bad ones are refused naming the key and line."""

from __future__ import annotations

from pathlib import Path

import pytest

from buddybot.sim import faces, scenario
from buddybot.sim.scenario import ScenarioError
from tests.sim import SCENARIOS

ISSUE_NAMES = {"visit", "passer_by", "two_people", "out_of_view", "return", "dark", "crowd",
               "ghost"}
HERE = SCENARIOS
GOOD = '''description = "one person"
length_s = 10

[[person]]
face = "collins"
path = [
    { t = 0, x = 2.0, y = 0.0 },
    { t = 5, x = 1.0, y = 0.0 },
]
'''


def test_every_promised_scenario_is_built_in_and_loads() -> None:
    assert set(scenario.builtin_names()) >= ISSUE_NAMES
    for name in scenario.builtin_names():
        loaded = scenario.load(name)
        assert loaded.name == name and loaded.spec.description


def test_the_tests_own_scenarios_load() -> None:
    for path in HERE.glob("*.toml"):
        assert scenario.load(str(path)).name == path.stem


def test_every_face_photo_is_there_with_its_licence() -> None:
    assert len(faces.names()) >= 4
    for name, face in faces.catalogue().items():
        assert faces.path(name).stat().st_size > 5000, name
        assert "public domain" in face.licence or "licen" in face.licence.lower(), name
        assert 0.3 < face.box_frac < 0.7


@pytest.mark.parametrize(("text", "line", "key", "reason"), [
    (GOOD.replace('face = "collins"', 'face = "nobody"'), 5, "person[0].face", "unknown face"),
    (GOOD.replace("x = 1.0", 'x = "far"'), 8, "person[0].path[1].x", "expected float"),
    (GOOD.replace("t = 5", "t = 0"), 8, "person[0].path[1].t", "not after"),
    (GOOD.replace("t = 5", "t = 50"), 8, "person[0].path[1].t", "after the scenario's end"),
    (GOOD.replace("length_s = 10", "length_s = 1e9"), 2, "length_s", "<= 86400"),
    (GOOD.replace("length_s = 10", "length_s = 10\nspeed = 2"), 3, "speed", "unknown key"),
    (GOOD.replace("y = 0.0 }", "y = 0.0, z = 1 }"), 7, "person[0].path[0].z", "unknown key"),
    (GOOD.replace("x = 2.0", "x = 900.0"), 7, "person[0].path[0].x", "<= 50"),
    (GOOD + '\n[[person]]\nface = "hopper"\nheight_m = 7\npath = [{ t = 1, x = 1, y = 0 }]\n',
     13, "person[1].height_m", "<= 2.5"),
])
def test_a_bad_file_names_the_key_and_its_line(text: str, line: int | None, key: str,
                                               reason: str) -> None:
    with pytest.raises(ScenarioError) as caught:
        scenario.parse(text, "bad.toml")
    message = str(caught.value)
    assert message.startswith("bad.toml") and reason in message, message
    if line is not None:
        assert f"line {line}, key '{key}'" in message, message
    assert "\n" not in message


def test_too_many_people_are_refused() -> None:
    one = '\n[[person]]\nface = "hopper"\npath = [{ t = 1, x = 1, y = 0 }]\n'
    text = GOOD + one * scenario.MAX_PEOPLE
    with pytest.raises(ScenarioError, match="person"):
        scenario.parse(text, "crowded.toml")


@pytest.mark.parametrize("text", ["not toml = = 1", "", "length_s = 'soon'", "\x00",
                                  "x = " + "[" * 5000 + "]" * 5000])
def test_not_a_scenario_is_one_clear_error(text: str) -> None:
    with pytest.raises(ScenarioError, match=r"^bad\.toml"):
        scenario.parse(text, "bad.toml")


def test_a_missing_or_huge_file_and_an_unknown_name(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"no such scenario; built in: .*visit"):
        scenario.load("party")
    with pytest.raises(ScenarioError, match="cannot read"):
        scenario.load(str(tmp_path / "gone.toml"))
    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * scenario.MAX_FILE_BYTES)
    with pytest.raises(ScenarioError, match="at most"):
        scenario.load(str(big))
