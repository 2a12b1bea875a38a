"""Shared fixtures: a real router on a free loopback port, processes cleaned up.

Also the marker rules, enforced rather than hoped for, so that
`pytest -m "not integration and not browser"` really is the fast unit suite:

* a test that uses a router or process fixture must be marked `integration`,
  and one that uses the `browser` fixture must be marked `browser`
  (checked from its fixture closure, before it runs);
* an unmarked test that starts a process itself (`subprocess`, directly or via
  `buddybot.tools.testing`) fails at that call, naming the marker it lacks.
"""

from __future__ import annotations

import os
import subprocess
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    InProcessRouter,
    Process,
    Router,
    closed_afterwards,
    run_service,
    stop_and_report,
)
from tests import cpu_usage, properties, robot_slots
from tests.camera.networks import Networks

properties.register()

ARTIFACTS = Path(os.environ.get("BUDDYBOT_ARTIFACTS", "test-artifacts"))

# Fixtures that start a router or processes (what the others build on; a test's
# fixture closure contains these whenever it uses anything derived from them).
INTEGRATION_FIXTURES = frozenset({
    "router", "router_process", "endpoint", "node_factory", "probe", "spawn",  # this file
    "tls_router", "host_node", "host_process", "started",  # tests/deploy/conftest.py
})
BROWSER_FIXTURES = frozenset({"browser"})  # tests/eyes/conftest.py
"""A module's tests that use these run on one xdist worker (a group of their own):
the fixture launches Chromium once per module and worker, about 1.7 CPU-s."""
MODEL_FIXTURES = frozenset({"networks", "embedder"})  # this file, tests/identity/conftest.py
"""Fixtures that load a real neural network: tests using them are marked `model`
(automatically, from the fixture closure) and run in the full suite only."""
TIMING = pytest.mark.xdist_group("timing")
"""For tests that bound delays, gaps or frame times, or that change the host's one
network stack (namespaces, veth and TAP devices): pytest-xdist (`--dist loadgroup`)
runs them all on one worker, so no two of them overlap and stretch each other's
times on a two-core machine."""
QUIET = pytest.mark.quiet
"""For tests that measure frame times in a browser (two pages drawing one blink
together): even one other busy worker on a two-core machine delays Chromium's
frames by tens of ms. `scripts/test.sh` runs them alone (`--phase quiet`, one
process), before everything else runs in parallel (`--phase rest`)."""
TESTS = Path(__file__).resolve().parent


def pytest_configure(config: pytest.Config) -> None:
    config.pluginmanager.register(cpu_usage, "buddybot-cpu-usage")  # BUDDYBOT_TEST_CPU=FILE


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--phase", choices=("all", "quiet", "rest"), default="all",
        help="all: every selected test; quiet: only those marked `quiet` (run them "
             "on an otherwise idle machine); rest: all but those (scripts/test.sh)")
TESTING_MODULE = Path(__file__).resolve().parents[1] / "services" / "tools" / "testing.py"


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """In `--phase quiet`, a test file whose text never says "quiet" is not even
    imported: it can hold no test with the marker, and importing all of them
    would cost the quiet phase, which runs alone, seconds of an idle machine."""
    if (config.getoption("phase") == "quiet" and collection_path.suffix == ".py"
            and collection_path.name.startswith("test_")
            and "quiet" not in collection_path.read_text(errors="replace").lower()):
        return True
    return None


def missing_markers(item: pytest.Item) -> list[str]:
    """The markers `item` needs for the fixtures it uses but does not carry."""
    used = set(getattr(item, "fixturenames", ()))
    need = []
    if used & INTEGRATION_FIXTURES and item.get_closest_marker("integration") is None:
        need.append(f"integration (it uses {', '.join(sorted(used & INTEGRATION_FIXTURES))})")
    if used & BROWSER_FIXTURES and item.get_closest_marker("browser") is None:
        need.append("browser (it uses the browser fixture)")
    return need


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests that load a network `model`, keep the tests of this `--phase`,
    then order them: tests with a router, processes or a browser first, the pure
    ones after.

    They take seconds each, the pure ones milliseconds: started first, the slow
    ones overlap on the pytest-xdist workers and the pure ones fill the gaps at
    the end, instead of one worker finishing a long system test alone."""
    for item in items:
        if set(getattr(item, "fixturenames", ())) & MODEL_FIXTURES:
            item.add_marker(pytest.mark.model)
    robot_slots.assign(items)
    for item in items:  # one Chromium per module (`browser`), not one per worker
        if (BROWSER_FIXTURES & set(getattr(item, "fixturenames", ()))
                and item.get_closest_marker("xdist_group") is None):
            item.add_marker(pytest.mark.xdist_group(f"browser-{item.path.stem}"))
    phase = config.getoption("phase")
    if phase != "all":
        keep = [i for i in items if (i.get_closest_marker("quiet") is not None) == (
            phase == "quiet")]
        dropped = [i for i in items if i not in keep]
        if dropped:
            config.hook.pytest_deselected(items=dropped)
        items[:] = keep

    def pure(item: pytest.Item) -> bool:
        return not (item.get_closest_marker("integration") or item.get_closest_marker("browser"))

    items.sort(key=pure)  # stable: each part keeps its collection order


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    """A `robot` test runs holding its machine-wide slot, any other test with
    processes or a browser one of the heavy slots (`robot_slots`); taken outside
    pytest-timeout's clock, so waiting for one is not the test's time."""
    slot = robot_slots.slot_of(item)
    if slot is not None:
        with robot_slots.held(slot):
            yield
    elif robot_slots.heavy(item):
        with robot_slots.any_heavy():
            yield
    else:
        yield


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Fail, before any fixture starts anything, a test whose markers do not say
    what it needs: a `-m "not integration"` run would otherwise be slow or hang."""
    need = missing_markers(item)
    if need:
        pytest.fail(f"{item.nodeid} must be marked {' and '.join(need)}", pytrace=False)


def _started_by_test_code() -> bool:
    """True if the innermost caller outside the subprocess module is test code
    (a test, a conftest, `buddybot.tools.testing`), not a library that happens to
    run a helper program (ctypes looking for a library, say)."""
    for frame in reversed(traceback.extract_stack()[:-2]):
        path = Path(frame.filename)
        if path.name == "subprocess.py" or path == Path(__file__).resolve():
            continue
        resolved = path.resolve()
        return resolved == TESTING_MODULE or TESTS in resolved.parents
    return False


@pytest.fixture(scope="session", autouse=True)
def _the_runs_own_state_folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The robot state folder (secrets, the gallery key) of everything this test run
    starts, its own: no service, command or test writes into the user's."""
    before = os.environ.get("BUDDYBOT_STATE_DIR")
    folder = tmp_path_factory.mktemp("robot-state")
    os.environ["BUDDYBOT_STATE_DIR"] = str(folder)
    yield folder
    if before is None:
        os.environ.pop("BUDDYBOT_STATE_DIR", None)
    else:
        os.environ["BUDDYBOT_STATE_DIR"] = before


@pytest.fixture(autouse=True)
def _processes_need_the_integration_marker(request: pytest.FixtureRequest,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """In a test not marked `integration`, starting a process from test code fails."""
    if request.node.get_closest_marker("integration") is not None:
        return
    original = subprocess.Popen.__init__

    def guarded(self: subprocess.Popen[Any], *args: Any, **kwargs: Any) -> None:
        if _started_by_test_code():
            argv = args[0] if args else kwargs.get("args")
            pytest.fail(f"{request.node.nodeid} starts a process ({argv!r:.120}): "
                        "mark it integration", pytrace=False)
        original(self, *args, **kwargs)

    monkeypatch.setattr(subprocess.Popen, "__init__", guarded)


@pytest.fixture(scope="session")
def networks() -> Networks:
    """The real face networks, each loaded once per test process (xdist worker)."""
    return Networks()


@pytest.fixture
def log_dir(tmp_path: Path) -> Path:
    return tmp_path / "logs"


@pytest.fixture
def router() -> Iterator[InProcessRouter]:
    """A Zenoh router in this test process on a free loopback port, closed afterwards
    (its port closed too). The services under test are processes all the same."""
    local = InProcessRouter()
    yield local
    local.stop()


@pytest.fixture
def router_process(log_dir: Path) -> Iterator[Router]:
    """A `buddybot router` process on a free loopback port, stopped afterwards: for
    a test that kills or restarts its router, or reads its log."""
    proc = Router(log_dir=log_dir)
    yield proc
    proc.stop()


@pytest.fixture
def endpoint(router: InProcessRouter) -> str:
    return router.endpoint


@pytest.fixture
def node_factory(endpoint: str) -> Iterator[Callable[..., Node]]:
    """Make in-process nodes connected to the test router; all closed afterwards."""
    def make(name: str = "probe", robot: str = "buddy", **kwargs: object) -> Node:
        return Node(name, robot=robot, connect=[endpoint], **kwargs)  # type: ignore[arg-type]

    yield from closed_afterwards(make)


@pytest.fixture
def probe(node_factory: Callable[..., Node]) -> Node:
    return node_factory("probe")


@pytest.fixture
def state_dir(tmp_path: Path) -> Path:
    """The robot state folder of the services a test spawns (secrets, gallery key):
    the test's own, never the user's."""
    return tmp_path / "state"


@pytest.fixture
def spawn(endpoint: str, log_dir: Path, state_dir: Path) -> Iterator[Callable[..., Process]]:
    """Start `buddybot run SERVICE ...` processes; every one is stopped afterwards.

    On failure their logs are printed, so a broken test shows what the
    services said. Their state folder is `state_dir` unless `env` says otherwise.
    """
    started: list[Process] = []

    def start(service: str, *args: str, robot: str = "buddy",
              env: dict[str, str] | None = None, nofile: int | None = None) -> Process:
        env = {"BUDDYBOT_STATE_DIR": str(state_dir), **(env or {})}
        proc = run_service(service, endpoint, *args, robot=robot, log_dir=log_dir, env=env,
                           nofile=nofile)
        started.append(proc)
        return proc

    yield start
    stop_and_report(started)
