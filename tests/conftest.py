"""Shared fixtures: a real router on a free loopback port, processes cleaned up."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from buddybot.core.node import Node
from buddybot.core.testing import Process, Router, run_service, stop_and_report

ARTIFACTS = Path(os.environ.get("BUDDYBOT_ARTIFACTS", "test-artifacts"))


@pytest.fixture
def log_dir(tmp_path: Path) -> Path:
    return tmp_path / "logs"


@pytest.fixture
def router(log_dir: Path) -> Iterator[Router]:
    """A `buddybot router` process on a free loopback port, stopped afterwards."""
    proc = Router(log_dir=log_dir)
    yield proc
    proc.stop()


@pytest.fixture
def endpoint(router: Router) -> str:
    return router.endpoint


@pytest.fixture
def node_factory(endpoint: str) -> Iterator[Callable[..., Node]]:
    """Make in-process nodes connected to the test router; all closed afterwards."""
    made: list[Node] = []

    def make(name: str = "probe", robot: str = "buddy", **kwargs: object) -> Node:
        node = Node(name, robot=robot, connect=[endpoint], **kwargs)  # type: ignore[arg-type]
        made.append(node)
        return node

    yield make
    for node in reversed(made):
        node.close()


@pytest.fixture
def probe(node_factory: Callable[..., Node]) -> Node:
    return node_factory("probe")


@pytest.fixture
def spawn(endpoint: str, log_dir: Path) -> Iterator[Callable[..., Process]]:
    """Start `buddybot run SERVICE ...` processes; every one is stopped afterwards.

    On failure their logs are printed, so a broken test shows what the
    services said.
    """
    started: list[Process] = []

    def start(service: str, *args: str, robot: str = "buddy",
              env: dict[str, str] | None = None) -> Process:
        proc = run_service(service, endpoint, *args, robot=robot, log_dir=log_dir, env=env)
        started.append(proc)
        return proc

    yield start
    stop_and_report(started)
