"""The node depends on its handles and diagnostics, never the other way round.

Why: a handle that reaches into the node (its session, its bookkeeping)
cannot be read, tested or changed without the whole node in mind. As in
rclpy, the node declares the Zenoh entity and hands it to the handle with
an `on_close` callback; diagnostics get a publisher and a callable. These
checks read the sources with `ast`, and are themselves checked on planted
sources so that they can fail.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

RUNTIME = Path(__file__).resolve().parents[1] / "services" / "runtime"
NODE_MODULE = "buddybot.runtime.node"


def _private(name: str) -> bool:
    """`_name`, not a dunder (`__name__`, `__init__` are public protocol)."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _from_module(item: ast.ImportFrom, package: str) -> str:
    """The absolute name of the module a `from ... import` in `package` reads."""
    if not item.level:
        return item.module or ""
    parent = package.rsplit(".", item.level - 1)[0]
    return f"{parent}.{item.module}" if item.module else parent


def _imported_modules(tree: ast.Module, package: str) -> list[str]:
    """Absolute names of what a module of `package` imports (from a module,
    each name is also listed as a possible submodule)."""
    found: list[str] = []
    for item in ast.walk(tree):
        if isinstance(item, ast.Import):
            found += [alias.name for alias in item.names]
        elif isinstance(item, ast.ImportFrom):
            base = _from_module(item, package)
            found += [base, *(f"{base}.{alias.name}" for alias in item.names)]
    return found


def entity_violations(source: str) -> list[str]:
    """What makes a handle-side module (handles, diagnostics) reach into the node:
    importing node.py, or reading a `_` attribute of anything but self/cls."""
    tree = ast.parse(source)
    problems = [f"imports {name}" for name in _imported_modules(tree, "buddybot.runtime")
                if name == NODE_MODULE]
    for item in ast.walk(tree):
        if isinstance(item, ast.Attribute) and _private(item.attr):
            owner = item.value
            if not (isinstance(owner, ast.Name) and owner.id in {"self", "cls"}):
                problems.append(f"line {item.lineno}: {ast.unparse(item)}")
    return problems


def node_violations(source: str) -> list[str]:
    """`_` names node.py takes from a runtime module: imported by name, or read
    as an attribute of a runtime module it imported."""
    tree = ast.parse(source)
    problems: list[str] = []
    modules: set[str] = set()  # local names bound to runtime modules
    for item in ast.walk(tree):
        if isinstance(item, ast.ImportFrom):
            base = _from_module(item, "buddybot.runtime")
            if base != "buddybot.runtime" and not base.startswith("buddybot.runtime."):
                continue
            for alias in item.names:
                if _private(alias.name):
                    problems.append(f"line {item.lineno}: {alias.name} from {base}")
                elif base == "buddybot.runtime":
                    modules.add(alias.asname or alias.name)
        elif isinstance(item, ast.Import):
            for alias in item.names:
                if alias.name.startswith("buddybot.runtime."):
                    if _private(alias.name.rsplit(".", 1)[1]):
                        problems.append(f"line {item.lineno}: {alias.name}")
                    modules.add(alias.asname or alias.name.split(".")[0])
    for item in ast.walk(tree):
        if (isinstance(item, ast.Attribute) and _private(item.attr)
                and ast.unparse(item.value).split(".")[0] in modules):
            problems.append(f"line {item.lineno}: {ast.unparse(item)}")
    return problems


@pytest.mark.parametrize("module", ["handles.py", "diagnostics.py"])
def test_handles_and_diagnostics_do_not_reach_into_the_node(module: str) -> None:
    assert entity_violations((RUNTIME / module).read_text()) == []


def test_the_node_uses_only_public_names_of_the_runtime() -> None:
    assert node_violations((RUNTIME / "node.py").read_text()) == []


@pytest.mark.parametrize("source", [
    "from buddybot.runtime.node import Node\n",
    "from buddybot.runtime import node\n",
    "import buddybot.runtime.node\n",
    "from .node import Node\n",
    "from . import node\n",
    "if TYPE_CHECKING:\n    from buddybot.runtime.node import Node\n",
    "def put(node):\n    return node._session\n",
    "class H:\n    def close(self):\n        self._node._forget(self)\n",
    "def watch(handle):\n    return handle._worker.dropped\n",
])
def test_the_entity_check_catches_a_reach_into_the_node(source: str) -> None:
    assert entity_violations(source), source


@pytest.mark.parametrize("source", [
    "from buddybot.runtime.handles import Publisher, error_text\n",
    "class H:\n    def close(self):\n        self._on_close(self)\n"
    "    @classmethod\n    def make(cls):\n        return cls._default\n",
    "def name(x):\n    return type(x).__name__\n",
])
def test_the_entity_check_accepts_one_way_code(source: str) -> None:
    assert entity_violations(source) == []


@pytest.mark.parametrize("source", [
    "from buddybot.runtime.handles import Handle, _Worker\n",
    "from .handles import _raw_reply\n",
    "from buddybot.runtime import handles\nw = handles._Worker\n",
    "import buddybot.runtime.handles\nw = buddybot.runtime.handles._Worker\n",
    "from buddybot.runtime import _private_module\n",
])
def test_the_node_check_catches_a_private_import(source: str) -> None:
    assert node_violations(source), source


@pytest.mark.parametrize("source", [
    "from buddybot.runtime.handles import Handle, Worker\n",
    "from buddybot.contract import keys\ndef f(e: keys._Entry) -> None: ...\n",
    "class Node:\n    def f(self):\n        return self._session\n",
])
def test_the_node_check_accepts_public_imports(source: str) -> None:
    assert node_violations(source) == []
