"""The controller as lease arbiter, as a process behind a real router: apps (nodes in
this process, or a child process killed with SIGKILL) take the eyes, the controller
puts their commands on `eyes/expression` and gives the eyes back when a lease ends."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import CallError
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until

from ..conftest import TIMING
from .conftest import FAST_CONFIG

X = m.ExpressionAction
Spawn = Callable[..., Process]
log = logging.getLogger("test.leases")

HOLDER = """
import sys, threading
from buddybot.contract import keys, messages as m
from buddybot.runtime.node import Node
node = Node("app-crashy", robot="buddy", connect=[sys.argv[1]])
reply = node.call(keys.LEASE_ACQUIRE, m.LeaseRequest(
    holder=node.name, instance=node.instance, resources=["expression", "gaze"]), timeout=10)
print("lease", reply.granted, reply.lease_id, reply.message, flush=True)
node.call(keys.EYES_COMMAND, m.EyesCommand(lease_id=reply.lease_id,
          expression=m.ExpressionAction.ANIMATE_STAR), timeout=10)
print("star shown", flush=True)
threading.Event().wait()
"""


@pytest.fixture
def controller(spawn: Spawn, tmp_path: Path, probe: Node) -> Process:
    """The controller of FAST_CONFIG, up (its lease services declared) and past its
    recovery (EYE_SLEEP shown)."""
    config = tmp_path / "robot.toml"
    config.write_text(FAST_CONFIG)
    expr: Collector[m.ScreenExpression] = Collector(probe, keys.EXPRESSION)
    proc = spawn("controller", "--config", str(config))
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP, timeout=20, what="initial EYE_SLEEP")

    def serving() -> bool:
        return any(keys.EYES_COMMAND.pattern in info.services
                   for info in probe.node_infos(timeout=1.0) if info.node == "controller")

    retry_until(serving, 20, what="the controller serving eyes/command")
    return proc


def acquire(node: Node, *resources: m.Resource, priority: m.LeasePriority = "app",
            duration_s: float | None = None) -> m.LeaseReply:
    reply: m.LeaseReply = node.call(keys.LEASE_ACQUIRE, m.LeaseRequest(
        holder=node.name, instance=node.instance, resources=list(resources),
        priority=priority, duration_s=duration_s), timeout=10)
    return reply


def express(node: Node, lease_id: str, action: X) -> m.TriggerReply:
    reply: m.TriggerReply = node.call(keys.EYES_COMMAND, m.EyesCommand(
        lease_id=lease_id, expression=action), timeout=10)
    return reply


@pytest.mark.integration
def test_a_holder_drives_the_eyes_and_a_late_screen_gets_one_value(
        controller: Process, node_factory: Callable[..., Node], probe: Node) -> None:
    app = node_factory("app-love")
    expr: Collector[m.ScreenExpression] = Collector(probe, keys.EXPRESSION)
    control: Collector[m.EyeControl] = Collector(probe, keys.EYE_CONTROL)
    states: Collector[m.Leases] = Collector(probe, keys.LEASES)
    lease = acquire(app, "expression", "gaze")
    assert lease.granted, lease.message
    states.wait_for(lambda s: [x.lease_id for x in s.leases] == [lease.lease_id],
                    what="the lease in leases/state")
    assert express(app, lease.lease_id, X.ANIMATE_LOVE).success
    expr.wait_for(lambda e: e.action == X.ANIMATE_LOVE, what="ANIMATE_LOVE on the bus")
    gaze = app.call(keys.EYES_COMMAND, m.EyesCommand(lease_id=lease.lease_id, yaw=0.3,
                                                     pitch=-0.1), timeout=10)
    assert gaze.success
    control.wait_for(lambda c: c.yaw == pytest.approx(0.3) and c.pitch == pytest.approx(-0.1),
                     what="the holder's gaze")

    # A screen starting now (a new subscriber: it asks the history of the latched
    # key) gets exactly one value, the holder's LOVE from the controller's publisher.
    late_sub = node_factory("late-screen")
    seen: Collector[m.ScreenExpression] = Collector(late_sub, keys.EXPRESSION)
    first = seen.wait_for(what="the latched expression")
    time.sleep(0.5)  # a second retained value would arrive in this time (not a sync)
    assert [e.action for e in seen.messages] == [X.ANIMATE_LOVE], seen.messages
    assert first.action == X.ANIMATE_LOVE

    # Released: the controller's own expression (EYE_SLEEP, nobody here) at once.
    done = app.call(keys.LEASE_RELEASE, m.LeaseRelease(lease_id=lease.lease_id,
                                                        by=app.name), timeout=10)
    assert done.success, done.message
    expr.wait_for(lambda e: e.action == X.EYE_SLEEP and e.stamp_ns > first.stamp_ns,
                  what="EYE_SLEEP back")
    ended = states.wait_for(lambda s: not s.leases and s.ended, what="the lease ended")
    assert ended.ended[-1].reason == "released"
    refused = express(app, lease.lease_id, X.ANIMATE_STAR)
    assert not refused.success and "released" in refused.message


@pytest.mark.integration
@TIMING
def test_a_killed_holder_gives_the_eyes_back_within_1_s(
        controller: Process, endpoint: str, log_dir: Path, probe: Node) -> None:
    expr: Collector[m.ScreenExpression] = Collector(probe, keys.EXPRESSION)
    states: Collector[m.Leases] = Collector(probe, keys.LEASES)
    holder = Process([sys.executable, "-c", HOLDER, endpoint], "app-crashy", log_dir)
    try:
        holder.wait_for_output("star shown", timeout=20)
        expr.wait_for(lambda e: e.action == X.ANIMATE_STAR, what="the app's STAR")
        expr.clear()
        killed = time.monotonic()
        holder.kill()
        back = expr.wait_for(lambda e: e.action == X.EYE_SLEEP, timeout=10,
                             what="the controller's EYE_SLEEP back")
        took = time.monotonic() - killed
    finally:
        holder.stop()
    print(f"kill -9 of the holder -> own expression back: {took * 1000:.0f} ms")
    log.warning("kill -9 of the holder -> own expression back: %.0f ms", took * 1000)
    assert back.action == X.EYE_SLEEP
    end = states.wait_for(lambda s: any(e.reason == "holder_gone" for e in s.ended),
                          what="holder_gone")
    assert end.ended[-1].holder == "app-crashy"
    assert took <= 1.0, f"{took:.2f} s"


@pytest.mark.integration
def test_an_operator_preempts_an_app_and_equals_queue(
        controller: Process, node_factory: Callable[..., Node], probe: Node) -> None:
    app, other, operator = (node_factory(n) for n in ("app-a", "app-b", "wizard"))
    expr: Collector[m.ScreenExpression] = Collector(probe, keys.EXPRESSION)
    first = acquire(app, "expression")
    assert first.granted
    second = acquire(other, "expression", "audio")
    assert not second.granted
    assert "app-a" in second.message and first.lease_id in second.message
    taken = acquire(operator, "expression", priority="operator")
    assert taken.granted and first.lease_id in taken.message
    stale = express(app, first.lease_id, X.ANIMATE_LOVE)
    assert not stale.success and "preempted" in stale.message
    assert express(operator, taken.lease_id, X.ANIMATE_STAR).success
    expr.wait_for(lambda e: e.action == X.ANIMATE_STAR, what="the operator's STAR")
    assert X.ANIMATE_LOVE not in [e.action for e in expr.messages]


@pytest.mark.integration
def test_bad_requests_are_refused_with_reasons_and_survived(
        controller: Process, node_factory: Callable[..., Node], endpoint: str) -> None:
    app = node_factory("app-bad")
    for duration, reason in ((0.0, "duration_s"), (-5.0, "duration_s"),
                             (1e12, "86400")):
        reply = acquire(app, "gaze", duration_s=duration)
        assert not reply.granted and reason in reply.message, reply
    builtin = acquire(app, "gaze", priority="builtin")
    assert not builtin.granted and "builtin" in builtin.message
    ghost = app.call(keys.LEASE_ACQUIRE, m.LeaseRequest(
        holder="ghost", instance="abc", resources=["gaze"]), timeout=10)
    assert not ghost.granted and "no liveliness token nodes/ghost/abc" in ghost.message

    session = zenoh.open(_client(endpoint))
    try:
        for key, payload in ((keys.LEASE_ACQUIRE, b'{"holder": 1}'),
                             (keys.LEASE_RELEASE, b"\xff garbage"),
                             (keys.EYES_COMMAND, b'{"lease_id": "x", "yaw": 99}')):
            replies = list(session.get(app.key(key), payload=payload, timeout=5.0))
            assert replies and replies[0].err is not None, key.pattern
            error = msgspec.json.decode(replies[0].err.payload.to_bytes(), type=m.ErrorReply)
            assert error.error.startswith("bad "), error
    finally:
        session.close()
    with pytest.raises(CallError):
        app.call_key(app.key(keys.EYES_COMMAND), keys.EYES_COMMAND,
                     m.Trigger(), timeout=5.0)  # type: ignore[arg-type]
    assert controller.alive()
    assert acquire(app, "gaze", duration_s=5.0).granted  # still serving


def _client(endpoint: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return conf


def lease_cli(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("lease", *args, "--connect", endpoint),
                          capture_output=True, text=True, timeout=60)


@pytest.mark.integration
def test_lease_list_and_break_from_the_command_line(
        controller: Process, node_factory: Callable[..., Node], endpoint: str,
        probe: Node) -> None:
    app = node_factory("app-cli")
    lease = acquire(app, "expression", "audio", duration_s=600)
    assert lease.granted
    listed = lease_cli(endpoint, "list")
    assert listed.returncode == 0, listed.stderr
    assert lease.lease_id in listed.stdout and "app-cli" in listed.stdout
    data = json.loads(lease_cli(endpoint, "list", "--json").stdout)
    assert [x["lease_id"] for x in data["leases"]] == [lease.lease_id]

    broken = lease_cli(endpoint, "break", lease.lease_id, "--reason", "demo over")
    assert broken.returncode == 0, broken.stdout + broken.stderr
    assert "broken" in broken.stdout
    again = lease_cli(endpoint, "break", lease.lease_id)
    assert again.returncode == 1 and "ended (broken)" in (again.stdout + again.stderr)
    usage = lease_cli(endpoint, "break")
    assert usage.returncode == 2
    after = json.loads(lease_cli(endpoint, "list", "--json").stdout)
    assert after["leases"] == []
    assert after["ended"][-1]["reason"] == "broken"
    assert after["ended"][-1]["message"] == "demo over"
