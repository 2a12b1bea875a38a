"""A running service answers `params/<node>` with a valid message (the `param` verb's
tests are tests/cli/test_param.py)."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process
from tests.cli.process import wait_params

pytestmark = pytest.mark.integration

Spawn = Callable[..., Process]


def test_a_reply_is_a_valid_message(spawn: Spawn, endpoint: str, probe: Node) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    reply = probe.call(keys.PARAMS, m.ParamRequest(op="get", name="range_m"),
                       node="radar-presence")
    assert isinstance(reply, m.ParamReply) and reply.params[0].value == 2.0
