"""SDK test helpers: bots connected to the test router (closed afterwards), a people
service to watch."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import Bot
from buddybot.tools.testing import Collector, Process


@pytest.fixture
def bot_factory(endpoint: str) -> Iterator[Callable[..., Bot]]:
    made: list[Bot] = []

    def make(**kwargs: object) -> Bot:
        kwargs.setdefault("timeout", 10.0)
        bot = Bot.connect(connect=[endpoint], **kwargs)  # type: ignore[arg-type]
        made.append(bot)
        return bot

    yield make
    for bot in reversed(made):
        bot.close()


def start_people(spawn: Callable[..., Process], probe: Node, tmp_path: Path) -> Process:
    """A `people` service (absence held 60 s), up once its first, empty, state came."""
    state = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
    config = tmp_path / "people.toml"
    config.write_text("[people]\nabsence_hold_s = 60\n")
    proc = spawn("people", "--config", str(config))
    state.wait_for(lambda s: s.people == [], 30, "the first, empty, people/state")
    return proc
