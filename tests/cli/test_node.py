"""`buddybot node info` as a process: what the node declared, and no answer."""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest

from buddybot.tools.testing import Process
from tests.cli.process import bb_on, wait_params

Spawn = Callable[..., Process]

pytestmark = pytest.mark.integration


def test_node_info_lists_what_the_node_declared(spawn: Spawn, endpoint: str) -> None:
    spawn("radar-presence")
    wait_params(endpoint, "radar-presence")
    result = bb_on(endpoint, "node", "info", "radar-presence")
    assert result.returncode == 0, result.stderr
    text = result.stdout
    publishers = text.split("publishers:")[1].split("subscriptions:")[0]
    assert "radar/presence" in publishers and "diagnostics/radar-presence" in publishers
    subscriptions = text.split("subscriptions:")[1].split("services:")[0]
    assert "radar/*/frames" in subscriptions
    assert "params/radar-presence" in text and "range_m = 2.0  (live)" in text
    report = json.loads(bb_on(endpoint, "node", "info", "radar-presence", "--json").stdout)
    assert "radar/presence" in report["info"]["publishers"]


def test_no_answer_gives_up_after_the_timeout(router: object, endpoint: str) -> None:
    info = bb_on(endpoint, "node", "info", "nobody-here", timeout="0.5")
    assert info.returncode == 1 and "did not answer" in info.stderr
