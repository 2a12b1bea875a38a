"""`buddybot lease list|break`: the table for people (pure), then the verb as a
process against a real router, eyes driver and controller."""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.cli.lease import table_lines
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, buddybot_argv

from ..eyes.test_arbiter import acquire
from ..eyes.test_arbiter import robot as robot  # the fixture

S = 1_000_000_000
T0 = 1_700_000_000 * S


def test_the_table_shows_every_lease_and_why_the_last_ones_ended() -> None:
    state = m.Leases(stamp_ns=T0, leases=[
        m.Lease(lease_id="L2-ab", holder="app-love", instance="z", priority="app",
                resources=["expression", "gaze"], granted_ns=T0, expires_ns=T0 + 90 * S),
        m.Lease(lease_id="L3-ab", holder="wizard", instance="z", priority="operator",
                resources=["audio"], granted_ns=T0)],
        ended=[m.LeaseEnd(lease_id="L1-ab", holder="app-x", reason="holder_gone",
                          stamp_ns=T0, message="no liveliness token nodes/app-x/q")])
    lines = table_lines(state, T0 + 30 * S)
    assert lines[0].split() == ["LEASE", "HOLDER", "PRIORITY", "RESOURCES", "SINCE", "EXPIRES"]
    assert lines[1].split()[:4] == ["L2-ab", "app-love", "app", "expression,gaze"]
    assert lines[1].endswith("in 60 s (" + lines[1].rsplit("(", 1)[1])
    assert lines[2].endswith("when released")
    assert lines[3] == "ended recently:"
    assert "L1-ab  app-x  holder_gone" in lines[4] and "nodes/app-x/q" in lines[4]
    assert table_lines(m.Leases(stamp_ns=T0), T0)[0].startswith("no leases")


def lease_cli(endpoint: str, *args: str, state: Path | None = None
              ) -> subprocess.CompletedProcess[str]:
    """The verb as the robot's owner runs it: the state folder (its operator secret)
    `state`, else one without any secret."""
    env = {**os.environ, "BUDDYBOT_STATE_DIR": str(state or Path("/nonexistent-state"))}
    return subprocess.run(buddybot_argv("lease", *args, "--connect", endpoint),
                          capture_output=True, text=True, timeout=60, env=env)


@pytest.mark.integration
def test_lease_list_and_break_from_the_command_line(
        robot: tuple[Process, Process], node_factory: Callable[..., Node], endpoint: str,
        probe: Node, state_dir: Path) -> None:
    app = node_factory("app-cli")
    lease = acquire(app, "expression", "audio", duration_s=600)
    assert lease.granted
    public = m.public_lease_id(lease.lease_id)
    listed = lease_cli(endpoint, "list")
    assert listed.returncode == 0, listed.stderr
    assert public in listed.stdout and "app-cli" in listed.stdout
    assert lease.lease_id not in listed.stdout  # the holder's handle is nobody else's
    data = json.loads(lease_cli(endpoint, "list", "--json").stdout)
    assert [x["lease_id"] for x in data["leases"]] == [public]

    stranger = lease_cli(endpoint, "break", public)  # no operator secret readable
    assert stranger.returncode == 2 and "operator secret" in stranger.stderr
    broken = lease_cli(endpoint, "break", public, "--reason", "demo over", state=state_dir)
    assert broken.returncode == 0, broken.stdout + broken.stderr
    assert "broken" in broken.stdout
    again = lease_cli(endpoint, "break", public, state=state_dir)
    assert again.returncode == 1 and "ended (broken)" in (again.stdout + again.stderr)
    usage = lease_cli(endpoint, "break", state=state_dir)
    assert usage.returncode == 2
    after = json.loads(lease_cli(endpoint, "list", "--json").stdout)
    assert after["leases"] == []
    assert after["ended"][-1]["reason"] == "broken"
    assert after["ended"][-1]["message"] == "demo over (by operator-cli)"
