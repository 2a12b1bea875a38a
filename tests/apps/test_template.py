"""`buddybot app new`'s template: valid Python, one app class named after the app."""

from __future__ import annotations

from pathlib import Path

import pytest

from buddybot.apps import load_app
from buddybot.apps.template import class_name, render


def test_the_template_is_an_app_named_as_asked(tmp_path: Path) -> None:
    path = tmp_path / "hello_world.py"
    path.write_text(render("hello_world"))
    loaded = load_app(str(path))
    assert loaded.cls.__name__ == "HelloWorld" and loaded.name == "hello_world"
    assert "buddybot app run hello_world.py" in path.read_text()


@pytest.mark.parametrize("name", ["", "9lives", "my-app", "a b", "../x", "hé"])
def test_names_that_cannot_be_a_file_a_class_and_a_node_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match="an app name starts with a letter"):
        render(name)


def test_class_names() -> None:
    assert class_name("hello") == "Hello"
    assert class_name("love_after_10s") == "LoveAfter10s"
