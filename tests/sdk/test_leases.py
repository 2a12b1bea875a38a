"""`buddybot.sdk.leases`: the runtime's errors as the SDK's, a lease's end and its
callbacks, following `leases/state` (pure), and, marked `integration`, a real
controller: a lease is granted, listed under the program's node name and released by
the context manager; a bad request raises; without a controller NoService; the Bot
is a visible node."""

from __future__ import annotations

import threading
from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import CallError, NoReplyError
from buddybot.runtime.leasing import LeaseRefused
from buddybot.runtime.node import Node
from buddybot.sdk import Bot, Lease, NoService, Refused, SdkError, TimedOut
from buddybot.sdk.leases import LeaseTable, arbiter_errors
from buddybot.tools.testing import Collector, Process, retry_until

# --- pure ----------------------------------------------------------------------------------


def test_the_runtime_s_lease_errors_become_the_sdk_s_naming_the_eyes_driver() -> None:
    with pytest.raises(Refused, match="audio is held by greeter") as refused, \
            arbiter_errors(keys.LEASE_ACQUIRE, 1.0):
        raise LeaseRefused("audio is held by greeter")
    assert refused.value.reason == "audio is held by greeter"
    with pytest.raises(NoService, match=r"nobody answered on eyes/command within 0\.5 s "
                                        r"\(is the eyes driver running\?"), \
            arbiter_errors(keys.EYES_COMMAND, 0.5):
        raise NoReplyError("eyes/command", "no reply")
    with pytest.raises(SdkError, match="leases/release: bad reply"), \
            arbiter_errors(keys.LEASE_RELEASE, 0.5):
        raise CallError("leases/release", "bad reply")


def test_a_lease_ends_once_and_calls_back_each_callback_once() -> None:
    lease = Lease(None, "L1", ("audio",), "app", 5.0)
    seen: list[str] = []
    lease.on_end(lambda ended: seen.append(f"a:{ended.ended}"))
    lease.on_end(lambda ended: 1 / 0)  # a failing callback is logged, not raised
    with pytest.raises(TimedOut, match=r"lease L1 on audio still held after 0\.01 s"):
        lease.wait(0.01)
    assert lease.holds("audio") and not lease.holds("gaze")
    assert lease.end("expired") and not lease.end("broken")
    lease.on_end(lambda ended: seen.append(f"late:{ended.ended}"))
    assert seen == ["a:expired", "late:expired"] and lease.wait(0) == "expired"
    assert not lease.active and not lease.holds("audio")
    lease.release()  # over already: nothing to ask


def _table(held: list[Lease]) -> LeaseTable:
    table = LeaseTable.__new__(LeaseTable)
    table._lock = threading.Lock()
    table._held = {lease.lease_id: lease for lease in held}
    table._seen = set()
    return table


def _listed(*ids: str) -> list[m.Lease]:
    return [m.Lease(lease_id=i, holder="app", instance="z", priority="app",
                    resources=["gaze"], granted_ns=1) for i in ids]


def test_the_state_ends_a_lease_it_lists_as_ended_or_stops_listing() -> None:
    a, b, c = (Lease(None, i, ("gaze",), "app", None) for i in ("A", "B", "C"))
    table = _table([a, b, c])
    assert table.changes(m.Leases(stamp_ns=1, leases=_listed("A", "B"))) == []
    end = m.LeaseEnd(lease_id="C", holder="app", reason="broken", stamp_ns=2,
                     message="broken by wizard")
    changes = table.changes(m.Leases(stamp_ns=2, leases=_listed("B"), ended=[end]))
    assert [(lease.lease_id, why, text) for lease, why, text in changes] == [
        ("A", "ended", "no longer in leases/state"), ("C", "broken", "broken by wizard")]
    assert table.holding("gaze") is a  # ended by whoever applies the changes, not here


# --- a real controller ---------------------------------------------------------------------


@pytest.mark.integration
def test_a_lease_is_granted_listed_under_the_program_and_released_on_leaving(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        probe: Node) -> None:
    controller()
    state = Collector[m.Leases](probe, keys.LEASES)
    bot = bot_factory(name="tester")
    retry_until(lambda: bot.node.instance in probe.node_instances().get("tester", set()),
                10, 0.1, "the bot's liveliness token")
    with bot.lease("eyes", "audio", duration_s=60) as lease:
        assert lease.active and lease.resources == ("expression", "gaze", "audio")
        listed = state.wait_for(lambda s: any(x.lease_id == lease.lease_id for x in s.leases),
                                10, "the lease listed")
        mine = next(x for x in listed.leases if x.lease_id == lease.lease_id)
        assert (mine.holder, mine.instance, mine.priority) == ("tester", bot.node.instance,
                                                               "app")
        assert bot.leases.holding("audio") is lease
    assert lease.ended == "released" and bot.leases.holding("audio") is None
    state.wait_for(lambda s: any(e.lease_id == lease.lease_id and e.reason == "released"
                                 for e in s.ended), 10, "the release in leases/state")


@pytest.mark.integration
def test_a_lease_broken_elsewhere_ends_here_with_the_reason(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot],
        probe: Node, operator_secret: str) -> None:
    controller()
    bot = bot_factory()
    lease = bot.lease("gaze")
    ended = threading.Event()
    lease.on_end(lambda _lease: ended.set())
    reply = probe.call(keys.LEASE_RELEASE, m.LeaseRelease(
        lease_id=lease.lease_id, by="wizard", credential=operator_secret), timeout=10)
    assert reply.success, reply.message
    assert ended.wait(10) and lease.ended == "broken" and "wizard" in lease.end_message


@pytest.mark.integration
def test_the_controller_refuses_what_it_does_not_grant_with_its_reason(
        controller: Callable[[], Process], bot_factory: Callable[..., Bot]) -> None:
    controller()
    bot = bot_factory()
    held = bot.lease("audio")
    with pytest.raises(Refused, match="audio is held by app at priority app"):
        bot.lease("audio")
    held.release()
    retry_until(lambda: bot.lease("audio").release() is None, 10, 0.1, "audio free again")


@pytest.mark.integration
def test_without_an_eyes_driver_a_lease_is_no_service(bot_factory: Callable[..., Bot],
                                                    probe: Node) -> None:
    bot = bot_factory(timeout=0.5)
    with pytest.raises(NoService, match=r"nobody answered on leases/acquire.*eyes driver"):
        bot.lease("eyes")
    with pytest.raises(NoService, match=r"nobody answered on leases/acquire"):
        bot.eyes.express("love")
    assert "app" in retry_until(lambda: probe.node_instances(), 10, 0.1, "the bot's token")
