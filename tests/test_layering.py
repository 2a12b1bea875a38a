"""The package's layers, as a test: who may import whom.

```
cli ─────────────────────────────────────────────┐
supervisor (up, status, router) ──┐              │
tools (probing, bag, doctor, ...)─┤   areas (radar, camera, ..., dashboard, foxglove)
                                  │              │         │ web surfaces / sim sensors
                                  │              │         v
                                  │              │   web (guard, auth, page_outbox)
                                  │              │   sim (the simulated world, scenarios)
                                  v              v         v
                runtime (node, handles, config, params, service, ...)
                                  v
                contract (messages, keys, schemas, describe, channels)
```

An area imports only the runtime, the contract and itself, so an area can
be lifted into its own repository (so can `sdk`, the library for
programs, which imports the same two layers, and `apps`, which adds the
sdk and which the sdk never imports). The controller, the robot's own
behaviour, is an app on the SDK: it imports the SDK, the contract's
messages and keys (pure data) and itself, never the runtime. The areas that serve a web page
(`WEB_SURFACES`) may also import `web`, the layer beside the runtime that
every web surface shares (who may connect, login, a page's sends); `web`
imports only the runtime and the contract. `sim`, the simulated world,
sits beside it: the areas that render that world (`SIM_SENSORS`)
and `up` (which gives every simulated sensor one world) may import it.
The runtime imports no tool,
no supervisor, no area and not `web`, so a service process loads only
what it runs. The rule is a table (`ALLOWED`), checked statically (every
`import` in the source, also the ones inside functions) and at run time
(what loading the runtime really loads), so a lazy import that slips past
is caught as well.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from buddybot.runtime import registry

SERVICES = Path(__file__).resolve().parents[1] / "services"
AREAS = ("radar", "camera", "controller", "eyes", "audio", "dashboard", "foxglove", "people",
         "ros2", "identity")
WEB_SURFACES = ("dashboard", "eyes", "foxglove")
"""The areas serving a web page or socket: only they may import `web`."""
SIM_SENSORS = ("radar", "camera")
"""The areas that render the simulated world (its sensors): only they may import `sim`."""
BASE = frozenset({"contract", "runtime"})
ALLOWED: dict[str, frozenset[str]] = {
    "contract": frozenset({"contract"}),
    "runtime": BASE,
    "tools": BASE | {"tools"},
    "supervisor": BASE | {"supervisor", "tools", "sim"},  # `up`: doctor, the world's start
    "web": BASE | {"web"},  # what every web surface shares (guard, login, page sends)
    "sim": BASE | {"sim"},  # the simulated world, its scenarios and its truth service
    **{area: BASE | {area} | ({"web"} if area in WEB_SURFACES else set())
       | ({"sim"} if area in SIM_SENSORS else set()) for area in AREAS},
    "controller": frozenset({"contract", "sdk", "controller"}),  # an app on the SDK
    "sdk": BASE | {"sdk"},  # programs of builders: the runtime only
    "apps": BASE | {"sdk", "apps"},  # apps and their runner stand on the sdk
    "cli": BASE | {"tools", "supervisor", "cli", "sdk", "apps", "web", "sim", *AREAS},
    "": frozenset({"cli"}),  # buddybot/__init__.py, __main__.py
}
"""Layer -> the layers its modules may import (a layer is a folder of `services/`)."""


def imports_of(path: Path) -> set[str]:
    """Every `buddybot...` module a file imports, anywhere in it."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            if node.module == "buddybot":
                found.update(f"buddybot.{a.name}" for a in node.names)
    return {name for name in found if name.split(".")[0] == "buddybot"}


def layer_of_module(module: str) -> str:
    """`buddybot.runtime.node` -> `runtime`; `buddybot` itself -> ``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def layer_of_path(path: Path, root: Path) -> str:
    rel = path.relative_to(root)
    return rel.parts[0] if len(rel.parts) > 1 else ""


def violations(root: Path) -> Iterator[str]:
    """One line per import that crosses the layers the wrong way, under `root`."""
    for path in sorted(root.rglob("*.py")):
        layer = layer_of_path(path, root)
        allowed = ALLOWED.get(layer)
        if allowed is None:
            yield f"{path.relative_to(root)}: folder {layer!r} is in no layer (add it to ALLOWED)"
            continue
        for module in sorted(imports_of(path)):
            target = layer_of_module(module)
            if target and target != "__version__" and target not in allowed:
                yield f"{path.relative_to(root)} imports {module} ({layer} may import "\
                      f"{', '.join(sorted(allowed))})"


def test_every_import_follows_the_layers() -> None:
    bad = list(violations(SERVICES))
    assert not bad, "\n".join(bad)


def test_only_the_layers_using_web_may_import_it() -> None:
    """`web` is granted to the layers that really use it, no more: a grant
    nobody uses is a door left open for the next import."""
    users = {layer_of_path(path, SERVICES) for path in SERVICES.rglob("*.py")
             if any(layer_of_module(m) == "web" for m in imports_of(path))}
    granted = {layer for layer, allowed in ALLOWED.items() if "web" in allowed}
    assert users - {"web"} == granted - {"web"} == {*WEB_SURFACES, "cli"}


@pytest.mark.integration
def test_the_controllers_decisions_load_neither_the_sdk_nor_the_runtime() -> None:
    """The behaviour's state machine, its geometry and its settings are pure: loading
    them loads the contract and nothing else (the SDK, and the runtime under it,
    come only with the service module that wires them to the bus)."""
    out = loaded_after("import buddybot.controller.behaviour, buddybot.controller.attention, "
                       "buddybot.controller.transform, buddybot.controller.settings")
    assert "buddybot.controller.behaviour" in out
    assert {layer_of_module(n) for n in out} == {"contract", "controller"}


def test_every_folder_is_a_layer() -> None:
    folders = {p.name for p in SERVICES.iterdir() if (p / "__init__.py").is_file()}
    assert folders == set(ALLOWED) - {""}


@pytest.mark.parametrize(("layer", "imported", "allowed"), [
    ("runtime", "buddybot.tools.bag", False),
    ("runtime", "buddybot.supervisor.launch", False),
    ("runtime", "buddybot.camera.pipeline", False),
    ("contract", "buddybot.runtime.node", False),
    ("foxglove", "buddybot.cli.topics", False),
    ("dashboard", "buddybot.tools.doctor", False),
    ("eyes", "buddybot.audio.sounds", False),
    ("tools", "buddybot.supervisor.launch", False),
    ("runtime", "buddybot.web.guard", False),
    ("contract", "buddybot.web.auth", False),
    ("radar", "buddybot.web.guard", False),
    ("identity", "buddybot.web.auth", False),
    ("sdk", "buddybot.web.page_outbox", False),
    ("web", "buddybot.dashboard.login", False),
    ("web", "buddybot.tools.doctor", False),
    ("eyes", "buddybot.runtime.node", True),
    ("dashboard", "buddybot.web.auth", True),
    ("web", "buddybot.runtime.endpoints", True),
    ("supervisor", "buddybot.tools.doctor", True),
    ("controller", "buddybot.runtime.node", False),
    ("controller", "buddybot.runtime.params", False),
    ("controller", "buddybot.people.model", False),
    ("controller", "buddybot.sdk.bot", True),
    ("controller", "buddybot.contract.keys", True),
])
def test_the_checker_catches_a_wrong_import(tmp_path: Path, layer: str, imported: str,
                                            allowed: bool) -> None:
    """The check itself can fail: a module planted in a copy of the layout that
    imports across the layers is reported, naming the file and the import."""
    for name in ALLOWED:
        if name:
            (tmp_path / name).mkdir()
            (tmp_path / name / "__init__.py").write_text("")
    (tmp_path / layer / "planted.py").write_text(f"def f() -> None:\n    import {imported}\n")
    found = list(violations(tmp_path))
    if allowed:
        assert found == []
    else:
        assert len(found) == 1 and f"{layer}/planted.py imports {imported}" in found[0]


def test_errors_is_a_leaf() -> None:
    assert imports_of(SERVICES / "runtime" / "errors.py") == set()


def test_node_imports_neither_the_config_nor_the_cli() -> None:
    names = imports_of(SERVICES / "runtime" / "node.py")
    assert not {n for n in names if n.startswith(("buddybot.runtime.config", "buddybot.cli"))}


def loaded_after(code: str) -> list[str]:
    """The `buddybot.*` modules a fresh interpreter holds after running `code`."""
    show = "print(' '.join(sorted(m for m in sys.modules if m.startswith('buddybot.'))))"
    probe = f"import sys\n{code}\n{show}\n"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True,
                          text=True, check=True, timeout=60).stdout.split()


@pytest.mark.integration
def test_loading_the_runtime_loads_only_the_runtime_and_the_contract() -> None:
    out = loaded_after("import buddybot.runtime.node, buddybot.runtime.service, "
                       "buddybot.runtime.config")
    assert "buddybot.runtime.node" in out  # the probe really ran
    assert [n for n in out if layer_of_module(n) not in BASE] == []


@pytest.mark.integration
def test_reading_a_config_loads_only_the_settings_modules() -> None:
    out = loaded_after("from buddybot.runtime.config import load_config\nload_config(None)")
    layers = (*AREAS, "sim")
    loaded = {name for name in out if layer_of_module(name) in layers}
    tables = {e.settings.partition(":")[0] for e in registry.SERVICES if e.settings}
    assert tables and tables <= loaded
    assert {n for n in loaded if not n.endswith((".settings", *(f".{a}" for a in layers)))} \
        == set()


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
    runtime = {"runtime/node.py", "runtime/session.py", "runtime/handles.py"}
    assert users == runtime | {"supervisor/router.py"}
