"""docs/architecture.md draws what the code wires, so the picture cannot drift.

The key catalogue (`contract/keys.py`) says what each key carries, not who
publishes or reads it, so the edges are derived from the code itself
(read, never run): for each service of the registry, the modules its
entry module imports (less the runtime core that every service imports),
and in them every `.publisher(keys.X)`, `.subscribe(keys.X)`,
`.serve(keys.X)` and `.call(keys.X)`. An edge `a -> b` on a topic is "a
publishes it, b subscribes"; on a service, "a calls it, b serves it".
Keys of each node (`{node}` in the pattern: diagnostics, params, node_info)
are everyone's and not drawn. A service written on the SDK (the controller)
wires the keys of the SDK calls it makes (`SDK_CALLS`), not of every SDK
module it loads; each of those keys is checked to be one the SDK uses.
The bridges (foxglove, ros2-bridge) also subscribe and serve keys chosen
at run time: only their named keys count.

The page holds the edges in two places, each edge once: the diagram (a
code block, one line per sender and key, `a --topic--> b, c` or
`a ==service==> b`) for the robot's own services, and the table
`| from | key | to |` for every edge of the operator's tools and bridges.
"""

from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path

from buddybot.contract import keys
from buddybot.runtime import registry

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
SERVICES_DIR = ROOT / "services"

OBSERVERS = frozenset({"dashboard", "foxglove", "ros2-bridge"})
"""The operator's tools and the bridges: their edges go in the table, not the diagram."""
BRIDGES = frozenset({"foxglove", "ros2-bridge"})
"""Services that may subscribe, serve or call keys chosen at run time."""
ROLES = {"publisher": "pub", "publisher_on": "pub", "subscribe": "sub", "subscribe_raw": "sub",
         "serve": "serve", "serve_raw": "serve", "call": "call", "call_key": "call",
         "query": "call"}
"""The node's methods, by the role they give their service in a key."""

SDK_CALLS: dict[str, set[tuple[str, keys.Topic | keys.Service]]] = {
    "on_state": {("sub", keys.PEOPLE_STATE)},
    "on_face": {("sub", keys.FACE)},
    "on_status": {("sub", keys.PLAY_SOUND_STATUS), ("sub", keys.LEASES)},
    "on_free": {("sub", keys.DEVICE_FREE)},
    "on_held": {("sub", keys.LEASES)},
    "play": {("call", keys.PLAY_SOUND)},
    "cancel": {("call", keys.PLAY_SOUND_CANCEL)},
    "express": {("pub", keys.BEHAVIOUR_EXPRESSION)},
    "look_at": {("pub", keys.BEHAVIOUR_GAZE)},
}
"""An SDK call (method name) made by a service's own code -> the (role, key) it
wires: the speaker follows the leases for its own; the built-in bot's
`express`/`look_at` are wishes."""

Edge = tuple[str, str, str]
"""(from service, key pattern, to service)."""


# --- what the code wires ---------------------------------------------------------------


def _path(module: str) -> Path | None:
    """The source of `buddybot.x.y` (None: not a module of the package)."""
    base = SERVICES_DIR.joinpath(*module.split(".")[1:])
    for path in (base / "__init__.py", base.with_suffix(".py")):
        if path.is_file():
            return path
    return None


@cache
def _tree(module: str) -> ast.Module:
    path = _path(module)
    assert path is not None, module
    return ast.parse(path.read_text(encoding="utf-8"))


def _imports(module: str) -> set[str]:
    found: set[str] = set()
    for node in ast.walk(_tree(module)):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found |= {f"{node.module}.{a.name}" for a in node.names}
    return {m for m in found if m.startswith("buddybot.") and _path(m) is not None}


def _closure(module: str, into_sdk: bool = True) -> set[str]:
    """`module` and every module it imports, transitively; not what only the
    SDK imports unless `into_sdk` (a service on the SDK wires its calls only)."""
    seen: set[str] = set()
    todo = [module]
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            if into_sdk or not _is_sdk(name):
                todo += _imports(name)
    return seen


def _catalogue_key(node: ast.expr) -> keys.Topic | keys.Service | None:
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
            and node.value.id == "keys":
        entry = getattr(keys, node.attr, None)
        return entry if isinstance(entry, keys.Topic | keys.Service) else None
    return None


def _uses(module: str) -> tuple[set[tuple[str, str]], list[str]]:
    """((role, key pattern) of every node call naming a catalogue key, the calls
    whose key is chosen at run time). A loop over a tuple of keys counts as
    naming each; `LiveSettings(...).serve(node)` names no key."""
    tree = _tree(module)
    loops: dict[str, list[keys.Topic | keys.Service]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.For) and isinstance(node.target, ast.Name) \
                and isinstance(node.iter, ast.Tuple | ast.List):
            entries = [_catalogue_key(e) for e in node.iter.elts]
            if entries and all(e is not None for e in entries):
                loops[node.target.id] = [e for e in entries if e is not None]
    uses: set[tuple[str, str]] = set()
    dynamic: list[str] = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr in ROLES and node.args):
            continue
        role, first = ROLES[node.func.attr], node.args[0]
        entry = _catalogue_key(first)
        if entry is not None:
            uses.add((role, entry.pattern))
        elif isinstance(first, ast.Name) and first.id in loops:
            uses |= {(role, e.pattern) for e in loops[first.id]}
        elif not (isinstance(first, ast.Name) and first.id == "node"):
            dynamic.append(f"{module}:{node.lineno} .{node.func.attr}({ast.unparse(first)})")
    return uses, dynamic


def _sdk_uses(module: str) -> set[tuple[str, str]]:
    """(role, key pattern) of every SDK call (`SDK_CALLS`) in `module`'s code."""
    return {(role, key.pattern) for node in ast.walk(_tree(module))
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
            for role, key in SDK_CALLS.get(node.func.attr, set())}


def _is_sdk(module: str) -> bool:
    return module == "buddybot.sdk" or module.startswith("buddybot.sdk.")


@cache
def _wiring() -> tuple[dict[str, set[tuple[str, str]]], dict[str, list[str]]]:
    """Per service: its (role, key) uses and its run-time-chosen calls."""
    core = set.intersection(*(_closure(e.module) for e in registry.SERVICES))
    """The runtime and the contract: every node's."""
    closures = {e.name: _closure(e.module, into_sdk=False) for e in registry.SERVICES}
    uses: dict[str, set[tuple[str, str]]] = {}
    dynamic: dict[str, list[str]] = {}
    for name, modules in closures.items():
        uses[name], dynamic[name] = set(), []
        on_sdk = any(_is_sdk(module) for module in modules)
        for module in sorted(modules - core):
            if _is_sdk(module):
                continue  # the library: its calls made by the service count, below
            found, chosen = _uses(module)
            uses[name] |= found | (_sdk_uses(module) if on_sdk else set())
            dynamic[name] += chosen
    return uses, dynamic


def code_edges() -> set[Edge]:
    """Every edge the code wires between two services (see the module's docstring)."""
    uses, _ = _wiring()
    other_end = {"pub": "sub", "call": "serve"}
    return {(a, key, b)
            for a, sent in uses.items() for b, taken in uses.items() if a != b
            for role, key in sent
            if role in other_end and "{node}" not in key and (other_end[role], key) in taken}


# --- what the page draws ---------------------------------------------------------------

ARROW = re.compile(r"^\s*(?P<a>[\w-]+)\s+(?P<kind>--|==)(?P<key>\S+?)(?:-->|==>)\s+(?P<to>.+?)\s*$")
"""A diagram line: `a --topic--> b, c` (published, subscribed) or `a ==service==> b`
(called, served)."""
ROW = re.compile(r"^\|\s*(?P<a>[\w-]+)\s*\|\s*`(?P<key>[^`]+)`(?P<service> \(service\))?\s*"
                 r"\|\s*(?P<to>[\w, -]+?)\s*\|\s*$")
"""An edge table row: `| a | `key` | b, c |`, `(service)` after a service's key."""


def _section(text: str) -> str:
    found = re.search(r"^## Processes and data$.*?(?=^## |\Z)", text, re.M | re.S)
    assert found, "docs/architecture.md has no section '## Processes and data'"
    return found.group(0)


def drawn(text: str) -> tuple[list[tuple[Edge, bool]], list[tuple[Edge, bool]]]:
    """(the diagram's edges, the table's edges) of the page's text, each with
    whether it is drawn as a service call."""
    section = _section(text)
    blocks = re.findall(r"^```\n(.*?)^```", section, re.M | re.S)
    diagram = [((m["a"], m["key"], to.strip()), m["kind"] == "==")
               for block in blocks for line in block.splitlines()
               if (m := ARROW.match(line)) for to in m["to"].split(",")]
    table = [((m["a"], m["key"], to.strip()), m["service"] is not None)
             for line in section.splitlines() if (m := ROW.match(line))
             for to in m["to"].split(",")]
    return diagram, table


def problems(text: str, edges: set[Edge]) -> list[str]:
    """What the page gets wrong against `edges` (empty: nothing)."""
    services = {key.pattern for key in keys.SERVICES}
    diagram, table = drawn(text)
    out: list[str] = []
    seen: list[Edge] = []
    for where, found in (("diagram", diagram), ("table", table)):
        for edge, as_call in found:
            a, key, b = edge
            seen.append(edge)
            if edge not in edges:
                out.append(f"the {where} draws {a} -> {b} on {key}, which the code does not "
                           f"wire ({a} does not send {key}, or {b} does not take it)")
            if as_call != (key in services):
                out.append(f"the {where} draws {key} as a "
                           f"{'service' if as_call else 'topic'}: it is not one")
            observed = a in OBSERVERS or b in OBSERVERS
            if observed != (where == "table"):
                out.append(f"{a} -> {b} on {key} belongs in the "
                           f"{'table' if observed else 'diagram'}")
    twice = sorted({e for e in seen if seen.count(e) > 1})
    out += [f"{a} -> {b} on {key} is drawn twice" for a, key, b in twice]
    out += [f"missing: {a} -> {b} on {key} ({'table' if {a, b} & OBSERVERS else 'diagram'})"
            for a, key, b in sorted(edges - set(seen))]
    named = {name for edge in seen for name in (edge[0], edge[2])}
    listed = set(re.findall(r"^\| `([\w-]+)` \|", _section(text), re.M))
    for entry in registry.SERVICES:
        if entry.name not in named:
            out.append(f"the service {entry.name} is in no edge")
        if entry.name not in listed:
            out.append(f"the service table has no row for `{entry.name}`")
    out += [f"the service table lists `{n}`, not a service of the registry"
            for n in sorted(listed - {e.name for e in registry.SERVICES})]
    return out


# --- the tests -------------------------------------------------------------------------


def test_the_page_draws_exactly_the_edges_the_code_wires() -> None:
    wrong = problems(ARCHITECTURE.read_text(encoding="utf-8"), code_edges())
    assert not wrong, "docs/architecture.md, 'Processes and data':\n" + "\n".join(wrong)


def test_the_derivation_sees_the_robot_s_wiring() -> None:
    """The reading of the code finds what is known to be wired (a reading that
    found nothing would pass an empty page)."""
    edges = code_edges()
    for edge in [("people", keys.PEOPLE_STATE.pattern, "controller"),
                 ("radar-bridge", keys.RADAR_FRAMES.pattern, "radar-presence"),
                 ("controller", keys.PLAY_SOUND.pattern, "audio"),
                 ("eyes", keys.PUPIL.pattern, "eye-renderer")]:
        assert edge in edges
    assert ("radar-presence", keys.PRESENCE.pattern, "controller") not in edges


def test_every_sdk_call_wires_a_key_the_sdk_uses() -> None:
    """`SDK_CALLS` cannot claim a key the SDK never touches: each is named by a node
    call (or the SDK's bounded `call(node, key, ...)`) in some SDK module."""
    sdk = sorted(m for m in _closure("buddybot.sdk") if _is_sdk(m))
    used: set[tuple[str, str]] = set()
    for module in sdk:
        used |= _uses(module)[0]
        for node in ast.walk(_tree(module)):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                    and node.func.id == "call" and len(node.args) > 1:
                entry = _catalogue_key(node.args[1])
                if entry is not None:
                    used.add(("call", entry.pattern))
    claimed = {(role, key.pattern) for wired in SDK_CALLS.values() for role, key in wired}
    assert sdk and claimed - used == set()


def test_only_the_bridges_choose_keys_at_run_time() -> None:
    """A key the reading cannot name is an edge it cannot see: only the bridges
    (foxglove, ros2-bridge) may have such calls."""
    _, dynamic = _wiring()
    unnamed = {name: calls for name, calls in dynamic.items() if calls and name not in BRIDGES}
    assert not unnamed, f"node calls whose key is not `keys.X` (name it): {unnamed}"


def test_a_planted_wrong_or_missing_edge_is_found() -> None:
    text = ARCHITECTURE.read_text(encoding="utf-8")
    edges = code_edges()
    assert not problems(text, edges)
    line = next(line for line in text.splitlines() if ARROW.match(line))
    stale = "radar-presence --radar/presence--> controller"
    planted = text.replace(line, f"{line}\n{stale}", 1)
    assert any("radar-presence -> controller on radar/presence" in p
               for p in problems(planted, edges))
    dropped = text.replace(line + "\n", "", 1)
    assert any(p.startswith("missing: ") for p in problems(dropped, edges))
    wrong_kind = text.replace("==audio/play_sound==>", "--audio/play_sound-->", 1)
    assert any("as a topic" in p for p in problems(wrong_kind, edges))
    in_table = text.replace("| dashboard | `audio/play_sound` (service) |",
                            "| dashboard | `audio/play_sound` |", 1)
    assert any("as a topic" in p for p in problems(in_table, edges))
