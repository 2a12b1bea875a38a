"""The package's layers: `core/` is a foundation the areas stand on, never the reverse.

Checked two ways: statically (every `import` in the source, also the ones
inside functions) and at run time (what loading the runtime really loads),
so a lazy import that slips an area into the runtime is caught as well.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

SERVICES = Path(__file__).resolve().parents[2] / "services"
AREAS = ("radar", "camera", "controller", "eyes", "audio")


def imports_of(path: Path) -> set[str]:
    """Every `buddybot...` module a file imports, anywhere in it."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{a.name}" for a in node.names)
    return {name for name in found if name.startswith("buddybot")}


def area_of(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in AREAS else None


@pytest.mark.parametrize("path", sorted((SERVICES / "core").glob("*.py")), ids=lambda p: p.name)
def test_core_never_imports_an_area(path: Path) -> None:
    bad = sorted(name for name in imports_of(path) if area_of(name))
    assert not bad, f"core/{path.name} imports {bad}: register it in core/registry.py instead"


@pytest.mark.parametrize("area", AREAS)
def test_areas_never_import_each_other(area: str) -> None:
    for path in sorted((SERVICES / area).glob("*.py")):
        others = sorted(n for n in imports_of(path) if area_of(n) not in (None, area))
        assert not others, f"{area}/{path.name} imports {others}"


def test_errors_is_a_leaf() -> None:
    assert imports_of(SERVICES / "core" / "errors.py") == set()


def test_node_imports_neither_the_config_nor_the_cli() -> None:
    names = imports_of(SERVICES / "core" / "node.py")
    assert not {n for n in names if n.startswith(("buddybot.core.config", "buddybot.cli"))}


@pytest.mark.integration
def test_loading_the_runtime_loads_no_area() -> None:
    probe = (
        "import sys, buddybot.core.node, buddybot.core.service, buddybot.core.config\n"
        "print(' '.join(sorted(m for m in sys.modules if m.startswith('buddybot.'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=60).stdout.split()
    assert "buddybot.core.node" in out  # the probe really ran
    assert [name for name in out if area_of(name)] == []


@pytest.mark.integration
def test_reading_a_config_loads_only_the_settings_modules() -> None:
    probe = (
        "import sys\n"
        "from buddybot.core.config import load_config\n"
        "load_config(None)\n"
        "print(' '.join(sorted(m for m in sys.modules if m.startswith('buddybot.'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=60).stdout.split()
    loaded = {name for name in out if area_of(name)}
    assert {f"buddybot.{a}.settings" for a in AREAS} <= loaded
    assert {n for n in loaded if not n.endswith((".settings", *(f".{a}" for a in AREAS)))} == set()


def test_node_is_the_only_door_to_zenoh() -> None:
    """Services and tools use `Node` handles; only the runtime (the node, its
    session and its handles) and the router process itself speak Zenoh."""
    users = set()
    for path in SERVICES.rglob("*.py"):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n == "zenoh" or n.startswith("zenoh.") for n in names):
                users.add(path.relative_to(SERVICES).as_posix())
    runtime = {"core/node.py", "core/session.py", "core/handles.py"}
    assert users == runtime | {"core/router.py"}
