"""App specs: FILE, MODULE or NAME told apart as text, and the node name each gives."""

from __future__ import annotations

import pytest

from buddybot.runtime.appspec import AppSpec, node_name, parse_app_spec


@pytest.mark.parametrize(("text", "spec"), [
    ("greeter.py", AppSpec("file", "greeter.py")),
    ("examples/apps/greeter.py", AppSpec("file", "examples/apps/greeter.py")),
    ("/abs/my app.py:Hello", AppSpec("file", "/abs/my app.py", "Hello")),
    ("mypkg.app", AppSpec("module", "mypkg.app")),
    ("mypkg.app:Greeter", AppSpec("module", "mypkg.app", "Greeter")),
    ("mymod:Greeter", AppSpec("module", "mymod", "Greeter")),
    ("greeter", AppSpec("name", "greeter")),
    ("my-app", AppSpec("name", "my-app")),
    ("  hello  ", AppSpec("name", "hello")),
])
def test_specs_are_classified(text: str, spec: AppSpec) -> None:
    assert parse_app_spec(text) == spec


@pytest.mark.parametrize(("text", "why"), [
    ("", "empty"),
    ("   ", "empty"),
    ("apps/greeter", "must end in .py"),
    ("a b", "is not an app"),
    ("pkg..mod", "is not an app"),
    ("pkg.mod:", "is not a class name"),
    ("pkg.mod:1x", "is not a class name"),
    ("my-app:Class", "is not an app"),
])
def test_malformed_specs_are_refused_with_the_reason(text: str, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        parse_app_spec(text)


def test_default_names_are_valid_node_names() -> None:
    assert parse_app_spec("examples/apps/love_after_10s.py").default_name == "love_after_10s"
    assert parse_app_spec("mypkg.greeter:Greeter").default_name == "greeter"
    assert parse_app_spec("my-app").default_name == "my-app"
    assert parse_app_spec("dir/my app!.py").default_name == "my-app"
    assert node_name("...") == "app"
    assert str(parse_app_spec("a/b.py:C")) == "a/b.py:C"
