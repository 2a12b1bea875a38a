"""SDK test helpers: bots connected to the test router, closed afterwards."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from buddybot.sdk import Bot


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
