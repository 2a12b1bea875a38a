"""`buddybot topics`: the table and the verb against real services."""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest

from buddybot.cli import topics as topics_cli
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, retry_until
from tests.cli.process import bb_on, wait_params

Spawn = Callable[..., Process]


def test_topics_table_names_publishers_and_subscribers() -> None:
    infos = [
        m.NodeInfo(node="bridge", instance="1", publishers=["radar/0/frames"]),
        m.NodeInfo(node="presence", instance="2", subscriptions=["radar/*/frames"],
                   publishers=["radar/presence"]),
    ]
    rows = {r.key: r for r in topics_cli.table({"radar/0/frames": 20}, 2.0, infos)}
    assert rows["radar/0/frames"].rate_hz == 10.0
    assert rows["radar/0/frames"].publishers == ["bridge"]
    assert rows["radar/0/frames"].subscribers == ["presence"]
    assert rows["radar/0/frames"].type == "LD2410TargetDataFrameArray"
    assert rows["radar/presence"].count == 0  # declared, silent in the window


@pytest.mark.integration
def test_topics_shows_keys_rates_and_who(spawn: Spawn, endpoint: str, probe: Node) -> None:
    spawn("radar-bridge", "--sim", "--device-id", "5")
    spawn("radar-presence")
    frames = probe.key(keys.RADAR_FRAMES, device="5")
    got: list[str] = []
    probe.subscribe_raw(frames, lambda key, _p, _e: got.append(key))
    retry_until(lambda: len(got) > 5, 30, what="frames flowing")
    wait_params(endpoint, "radar-presence")
    result = bb_on(endpoint, "topics", "--json", timeout="3")
    assert result.returncode == 0, result.stderr
    rows = {r["key"]: r for r in json.loads(result.stdout)}
    row = rows["radar/5/frames"]
    assert 5.0 <= row["rate_hz"] <= 15.0  # the simulated LD2410 reports at 10 Hz
    assert row["publishers"] == ["radar-bridge"]
    # This test's own node ("probe", a full node) subscribes too; `topics` itself does not.
    assert row["subscribers"] == ["probe", "radar-presence"]
    assert row["type"] == "LD2410TargetDataFrameArray"
    assert "diagnostics/radar-presence" in rows
    text = bb_on(endpoint, "topics", timeout="2").stdout
    assert any(line.startswith("radar/5/frames") and "radar-bridge -> probe, radar-presence" in line
               for line in text.splitlines())
