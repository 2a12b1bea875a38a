"""Finding an app's class from a file, a module or an installed name, and every way
that fails: one line, AppError (exit 2)."""

from __future__ import annotations

import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from buddybot.apps import App, AppError, installed_apps, load_app
from buddybot.runtime.errors import EXIT_USAGE, exit_status

SYNC = """
import threading
class Hello:
    def run(self, bot, stop_event):
        stop_event.wait()
"""
ASYNC_NAMED = """
from buddybot.apps import App
class Wave(App):
    name = "waver"
    async def run(self, bot, stop_event):
        pass
"""
TWO = """
class A:
    def run(self, bot, stop_event): ...
class B:
    def run(self, bot, stop_event): ...
"""


def write(folder: Path, name: str, code: str) -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(code))
    return path


@pytest.fixture
def on_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A folder on sys.path for modules (and dist-infos) of the test; imports forgotten after."""
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - before:
        del sys.modules[name]


def test_a_file_with_one_app_class(on_path: Path) -> None:
    path = write(on_path, "hello.py", SYNC)
    loaded = load_app(str(path))
    assert loaded.cls.__name__ == "Hello" and loaded.name == "hello"
    assert loaded.spec.kind == "file"


def test_the_class_name_wins_over_the_file_name(on_path: Path) -> None:
    loaded = load_app(str(write(on_path, "wave_app.py", ASYNC_NAMED)))
    assert loaded.cls.__name__ == "Wave" and loaded.name == "waver"
    assert issubclass(loaded.cls, App)  # App itself, imported, is not a candidate


def test_two_candidates_are_refused_unless_one_is_named(on_path: Path) -> None:
    path = write(on_path, "two.py", TWO)
    with pytest.raises(AppError, match=r"2 app classes \(A, B\); choose one with .*two.py:Class"):
        load_app(str(path))
    assert load_app(f"{path}:B").cls.__name__ == "B"
    with pytest.raises(AppError, match="no class 'C'"):
        load_app(f"{path}:C")


def test_modules_with_and_without_a_class(on_path: Path) -> None:
    (on_path / "mypkg").mkdir()
    (on_path / "mypkg" / "__init__.py").write_text("")
    write(on_path / "mypkg", "hello.py", SYNC)
    write(on_path / "mypkg", "two.py", TWO)
    assert load_app("mypkg.hello").cls.__name__ == "Hello"
    assert load_app("mypkg.hello").name == "hello"
    assert load_app("mypkg.two:A").cls.__name__ == "A"
    write(on_path, "toplevel.py", SYNC)
    assert load_app("toplevel").cls.__name__ == "Hello"  # a NAME not installed: a module


def test_an_installed_app_is_found_by_its_entry_point(on_path: Path) -> None:
    write(on_path, "acme_apps.py", SYNC + TWO)
    info = on_path / "acme_apps-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-apps\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[buddybot.apps]\nhello = acme_apps:Hello\nbroken = acme_apps:Nope\n"
        "many = acme_apps\n")
    assert installed_apps()["hello"] == "acme_apps:Hello"
    loaded = load_app("hello")
    assert loaded.cls.__name__ == "Hello" and loaded.name == "hello"
    with pytest.raises(AppError, match=r"installed app 'broken'.*failed to import"):
        load_app("broken")
    with pytest.raises(AppError, match=r"installed app 'many'.*3 app classes"):
        load_app("many")


@pytest.mark.parametrize(("code", "why"), [
    ("x = 1\n", "no app class"),
    ("class A:\n    def run(self, bot): ...\n",
     r"run\(self, bot\) must take \(self, bot, stop_event\)"),
    ("class A:\n    def run(self): ...\n", "must take"),
    ("class A:\n    def __init__(self, x): ...\n    def run(self, bot, stop_event): ...\n",
     r"made without arguments, not A\(x\)"),
    ("from buddybot.apps import App\nclass A(App):\n    pass\n", "defines no run"),
    ("import nothing_such_here\n", "(?s)failed to import:\n.*No module named 'nothing_such_here'"),
    ("def broken(:\n", "(?s)failed to import:\n.*bad.py\", line 1.*SyntaxError"),
])
def test_bad_app_files_are_refused_with_the_reason(on_path: Path, code: str, why: str) -> None:
    path = write(on_path, "bad.py", code)
    with pytest.raises(AppError, match=why) as error:
        load_app(str(path))
    assert str(error.value).startswith(str(path))
    assert exit_status(error.value) == EXIT_USAGE  # `up` does not restart it


@pytest.mark.parametrize(("spec", "why"), [
    ("nothere.py", "nothere.py: no such file"),
    ("no_such_pkg.mod", "no module 'no_such_pkg.mod'"),
    ("no_such_app_anywhere", "no module 'no_such_app_anywhere' and no installed app of that name"),
    ("a b", "is not an app"),
])
def test_what_does_not_exist_is_named(spec: str, why: str) -> None:
    with pytest.raises(AppError, match=why):
        load_app(spec)
