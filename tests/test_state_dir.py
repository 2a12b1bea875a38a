"""One state-folder setting for every service and tool: `BUDDYBOT_STATE_DIR`.

What the robot keeps (the identity gallery and its key, the web surfaces'
secrets) lives in one folder, chosen by one rule written once
(`runtime.private_files.state_dir`: `$BUDDYBOT_STATE_DIR`, systemd's
`$STATE_DIRECTORY`, `$XDG_STATE_HOME/buddybot`, `~/.local/state/buddybot`). A
service that had its own rule would ignore the setting, and two robot ids of
one user would share its files. Checked two ways:

* statically: no module but private_files reads the variables of the rule
  or a home folder, and every module that writes a file is listed here as
  either a state writer (and then names `state_dir`) or a writer of a path
  the user gives (a recording, a dump): a new writer fails until classified;
* by behaviour: with the variable set, every default state path lies in it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from buddybot.runtime import private_files

SERVICES = Path(__file__).resolve().parents[1] / "services"
RULE_OWNER = "runtime/private_files.py"
RULE_WORDS = ("BUDDYBOT_STATE_DIR", "STATE_DIRECTORY", "XDG_STATE_HOME", ".local/state")
"""Text only the rule's own module may hold (a docstring may name the setting)."""

STATE_WRITERS = {
    "identity/gallery.py": "the gallery and its key",
    "identity/service.py": "the gallery's default place",
    "web/auth.py": "the web surfaces' secrets",
}
"""Modules writing the robot's state: each takes its folder from `state_dir`."""
OTHER_WRITERS = {
    "runtime/private_files.py": "the rule itself and the atomic owner-only write",
    "runtime/session.py": "reopens stdout, not a file",
    "audio/tts.py": "a cache of rendered speech in the temporary folder, not state",
    "audio/player_service.py": "--tap FILE: a path the user gives",
    "audio/player.py": "opens /dev/null",
    "ros2/rosbag.py": "a recording where the user says",
    "contract/schemas.py": "`buddybot schemas --out`: a path the user gives",
    "cli/param.py": "`param dump --output`: a path the user gives",
    "cli/echo.py": "opens /dev/null",
    "cli/app.py": "`app new`: a file the user names",
    "tools/bag.py": "a recording where the user says",
    "tools/bag_recover.py": "a recovered recording where the user says",
    "tools/testing.py": "test helpers: temporary folders",
}
"""Modules writing files that are not the robot's state, and why."""


def _module(path: Path) -> str:
    return path.relative_to(SERVICES).as_posix()


def _writes(tree: ast.AST) -> bool:
    """Whether a module writes a file: write_text/write_bytes/write_private/mkdir, an
    `open` with a writing mode, an `os.open` (creating flags are only used to write)."""
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
        if name in ("write_text", "write_bytes", "write_private", "mkdir"):
            return True
        if name == "open" and isinstance(func, ast.Name):
            modes = [a for a in node.args[1:2]] + [k.value for k in node.keywords
                                                   if k.arg == "mode"]
            if any(isinstance(m, ast.Constant) and isinstance(m.value, str)
                   and set(m.value) & set("wax+") for m in modes):
                return True
        if name == "open" and isinstance(func, ast.Attribute) \
                and ast.unparse(func.value) == "os" and "O_CREAT" in ast.unparse(node):
            return True
    return False


def _sources() -> dict[str, tuple[str, ast.AST]]:
    return {_module(p): (p.read_text(), ast.parse(p.read_text(), str(p)))
            for p in sorted(SERVICES.rglob("*.py"))}


def test_only_the_rule_reads_the_state_folder_variables() -> None:
    found = {}
    for module, (text, tree) in _sources().items():
        if module == RULE_OWNER:
            continue
        docs = _docstrings(tree)
        code = [n for n in ast.walk(tree) if isinstance(n, ast.Constant)
                and isinstance(n.value, str) and id(n) not in docs]
        words = [w for w in RULE_WORDS if any(w in c.value for c in code)]
        if "Path.home" in text or "expanduser(\"~" in text:
            words.append("a home folder")
        if words:
            found[module] = words
    assert not found, f"a state-folder rule of their own (use private_files.state_dir): {found}"


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring nodes of a module and its classes and functions."""
    found = set()
    for owner in ast.walk(tree):
        body = getattr(owner, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) \
                and isinstance(body[0].value, ast.Constant):
            found.add(id(body[0].value))
    return found


def test_every_file_writer_is_classified_and_state_comes_from_state_dir() -> None:
    sources = _sources()
    writers = {m for m, (_, tree) in sources.items() if _writes(tree)}
    known = set(STATE_WRITERS) | set(OTHER_WRITERS)
    assert not writers - known, (
        f"modules writing files that are not classified: {sorted(writers - known)}; "
        "robot state belongs in private_files.state_dir(), add them to STATE_WRITERS")
    assert not known - set(sources), f"classified but gone: {sorted(known - set(sources))}"
    for module in STATE_WRITERS:
        assert "state_dir" in sources[module][0], f"{module} writes state elsewhere"


def test_the_rule_finds_a_writer_and_a_rule_of_its_own() -> None:
    """The checks above can fail: a made-up module of each kind is caught."""
    writer = ast.parse("from pathlib import Path\nPath('x').write_text('y')\n")
    assert _writes(writer)
    assert _writes(ast.parse("f = open(p, 'wb')\n"))
    assert not _writes(ast.parse("f = open(p, 'rb')\n"))
    assert _writes(ast.parse("import os\nos.open(p, os.O_WRONLY | os.O_CREAT)\n"))
    own = ast.parse('"""Uses BUDDYBOT_STATE_DIR."""\nX = "BUDDYBOT_STATE_DIR"\n')
    consts = [n for n in ast.walk(own) if isinstance(n, ast.Constant)]
    assert [id(c) in _docstrings(own) for c in consts] == [True, False]


def test_every_default_state_path_is_in_the_configured_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from buddybot.identity import gallery
    from buddybot.identity.settings import GALLERY_FILE
    from buddybot.web import auth as web_auth

    for robot in ("a", "b"):  # two robot ids of one user: two folders
        folder = tmp_path / robot
        monkeypatch.setenv("BUDDYBOT_STATE_DIR", str(folder))
        paths = [private_files.state_dir() / GALLERY_FILE, gallery.key_path(),
                 private_files.secret_file(private_files.OPERATOR_SECRET),
                 *(web_auth.secret_path(role) for role in web_auth.ROLES),
                 web_auth.state_dir()]
        for path in paths:
            assert path.is_relative_to(folder), (robot, path)
