"""SDK test helpers: bots connected to the test router (closed afterwards), a people
service to watch."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.private_files import secret_file, write_private
from buddybot.sdk import Bot
from buddybot.tools.testing import Collector, Process, closed_afterwards, retry_until


@pytest.fixture
def bot_factory(endpoint: str) -> Iterator[Callable[..., Bot]]:
    def make(**kwargs: object) -> Bot:
        kwargs.setdefault("timeout", 10.0)
        return Bot.connect(connect=[endpoint], **kwargs)  # type: ignore[arg-type]

    yield from closed_afterwards(make)


def start_people(spawn: Callable[..., Process], probe: Node, tmp_path: Path) -> Process:
    """A `people` service (absence held 60 s), up once its first, empty, state came."""
    state = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
    config = tmp_path / "people.toml"
    config.write_text("[people]\nabsence_hold_s = 60\n")
    proc = spawn("people", "--config", str(config))
    state.wait_for(lambda s: s.people == [], 30, "the first, empty, people/state")
    return proc


CONTROLLER_CONFIG = "[controller]\nrecover_s = 0.3\n"


@pytest.fixture
def operator_secret(state_dir: Path) -> str:
    """The robot's operator secret, in the state folder the spawned eyes driver reads."""
    secret = "the-robots-operator-secret"
    write_private(secret_file("operator", state_dir), secret.encode() + b"\n")
    return secret


@pytest.fixture
def controller(spawn: Callable[..., Process], probe: Node, tmp_path: Path
               ) -> Callable[[], Process]:
    """Start the eyes driver (the arbiter) and a `controller` (no inputs: its own
    expression is EYE_SLEEP), returning the controller once the eyes driver serves
    `leases/acquire` and `eyes/command` and shows the controller's expression."""
    def start() -> Process:
        expr = Collector[m.ScreenExpression](probe, keys.EXPRESSION)
        config = tmp_path / "controller.toml"
        config.write_text(CONTROLLER_CONFIG)
        spawn("eyes", "--config", str(config))
        retry_until(lambda: any(i.node == "eyes" and "leases/acquire" in i.services
                                and "eyes/command" in i.services
                                for i in probe.node_infos(1.0)),
                    30, 0.2, "the eyes driver serving leases")
        proc = spawn("controller", "--config", str(config))
        expr.wait_for(lambda e: e.action == m.ExpressionAction.EYE_SLEEP, 30,
                      "the controller's own EYE_SLEEP")
        return proc
    return start
