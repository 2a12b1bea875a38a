"""`buddybot.sdk.params` against a running `people` service (marked `integration`):
a get, a live set, a refused set with the node's reason, a node that does not answer."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.runtime.node import Node
from buddybot.sdk import Bot, NoService, Refused
from buddybot.tools.testing import Process
from tests.sdk.conftest import start_people

pytestmark = pytest.mark.integration


def test_get_and_set_a_live_parameter(spawn: Callable[..., Process], probe: Node,
                                      bot_factory: Callable[..., Bot], tmp_path: Path) -> None:
    start_people(spawn, probe, tmp_path)
    bot = bot_factory()
    assert bot.params.get("people", "absence_hold_s") == 60.0
    assert bot.params.set("people", "engage_dwell_s", 0.5) is True
    assert bot.params.get("people", "engage_dwell_s") == 0.5
    assert bot.params.set("people", "engage_dwell_s", 0.5) is False
    with pytest.raises(Refused, match=r"people: .*tick_s needs a restart"):
        bot.params.set("people", "tick_s", 0.1)
    with pytest.raises(Refused, match="has no parameter 'nope'"):
        bot.params.get("people", "nope")
    with pytest.raises(NoService, match=r"on params/nobody .*node nobody is not running"):
        bot.params.get("nobody", "x", timeout=0.5)
