"""The lease rule book without Zenoh: every rule, every refusal with its reason."""

from __future__ import annotations

import math

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.eyes.leases import ENDED_KEPT, MAX_LEASES, MAX_PER_HOLDER, LeaseTable

X = m.ExpressionAction
S = 1_000_000_000
T0 = 1_700_000_000 * S


def req(holder: str = "app-a", *resources: m.Resource, priority: m.LeasePriority = "app",
        duration_s: float | None = None, instance: str = "i1") -> m.LeaseRequest:
    return m.LeaseRequest(holder=holder, instance=instance,
                          resources=list(resources) or ["expression"], priority=priority,
                          duration_s=duration_s)


def grant(table: LeaseTable, request: m.LeaseRequest, at: int = T0) -> m.LeaseReply:
    """Granted (an operator request as if its credential were right)."""
    decision = table.acquire(request, at, True, operator=request.priority == "operator")
    assert decision.reply.granted, decision.reply.message
    return decision.reply


def test_a_free_resource_is_granted_with_a_unique_id() -> None:
    table = LeaseTable(run_tag="t")
    first = grant(table, req("app-a", "expression", "gaze"))
    second = grant(table, req("app-b", "audio"))
    assert m.public_lease_id(first.lease_id) == "L1-t"
    assert m.public_lease_id(second.lease_id) == "L2-t"
    assert first.lease_id.startswith("L1-t.") and len(first.lease_id) > 20  # the handle
    assert table.snapshot(T0).leases[0].lease_id == "L1-t"  # the bus sees no secret
    assert table.held() == ["expression", "gaze", "audio"]
    owner = table.owner("gaze")
    assert owner is not None and owner.holder == "app-a" and owner.granted_ns == T0
    assert table.counters["leases_granted"] == 2
    assert LeaseTable().acquire(req(), T0, True).reply.lease_id != \
        LeaseTable().acquire(req(), T0, True).reply.lease_id  # random per run


def test_equals_are_first_come_first_served_and_the_holder_is_named() -> None:
    table = LeaseTable(run_tag="t")
    grant(table, req("app-a", "expression"))
    refused = table.acquire(req("app-b", "gaze", "expression"), T0, True)
    assert not refused.reply.granted and refused.ended == []
    assert refused.reply.message == "expression is held by app-a at priority app (lease L1-t)"
    assert table.owner("gaze") is None  # nothing of a refused request is taken
    assert table.counters["leases_refused"] == 1


def test_a_lower_priority_is_refused_by_a_higher_one() -> None:
    table = LeaseTable(run_tag="t")
    grant(table, req("wizard", "gaze", priority="operator"))
    refused = table.acquire(req("app-a", "gaze"), T0, True).reply
    assert not refused.granted and "wizard at priority operator" in refused.message


def test_a_higher_priority_preempts_lower_leases_whole() -> None:
    table = LeaseTable(run_tag="t")
    grant(table, req("app-a", "expression", "audio"))
    grant(table, req("app-b", "gaze"))
    decision = table.acquire(req("wizard", "expression", "gaze", priority="operator"),
                             T0 + S, True, operator=True)
    assert decision.reply.granted
    assert [(e.lease_id, e.reason) for e in decision.ended] == [("L1-t", "preempted"),
                                                                ("L2-t", "preempted")]
    assert "L1-t (app-a)" in decision.reply.message
    assert table.owner("audio") is None  # ended whole: its audio is free again
    assert [x.holder for x in table.snapshot(T0).leases] == ["wizard"]


@pytest.mark.parametrize(("duration", "why"), [
    (0.0, "duration_s 0.0 must be > 0"), (-1.0, "must be > 0"), (math.inf, "must be > 0"),
    (math.nan, "must be > 0"), (m.MAX_LEASE_S + 1, "<= 86400"),
])
def test_absurd_durations_are_refused_with_the_reason(duration: float, why: str) -> None:
    reply = LeaseTable().acquire(req(duration_s=duration), T0, True).reply
    assert not reply.granted and why in reply.message


def test_other_bad_requests_are_refused_with_the_reason() -> None:
    table = LeaseTable()
    builtin = table.acquire(req(priority="builtin"), T0, True).reply
    assert not builtin.granted and "builtin" in builtin.message
    twice = table.acquire(req("app-a", "gaze", "gaze"), T0, True).reply
    assert not twice.granted and "repeat" in twice.message
    dead = table.acquire(req("app-a", instance="z9"), T0, False).reply
    assert not dead.granted
    assert dead.message == "holder not alive: no liveliness token nodes/app-a/z9"
    assert dead.message.startswith(m.HOLDER_NOT_ALIVE)
    assert len(table) == 0 and table.counters["leases_refused"] == 3
    assert table.counters["holders_not_alive"] == 1


def test_a_day_is_the_longest_lease_and_it_expires() -> None:
    table = LeaseTable()
    reply = grant(table, req(duration_s=m.MAX_LEASE_S))
    assert reply.expires_ns == T0 + 86400 * S
    short = grant(table, req("app-b", "gaze", duration_s=2.5))
    assert table.expire(T0 + 2 * S) == []
    ended = table.expire(T0 + 2_500_000_000)
    assert [(e.lease_id, e.reason) for e in ended] == [(m.public_lease_id(short.lease_id),
                                                        "expired")]
    assert table.owner("gaze") is None and table.owner("expression") is not None


def test_release_by_the_holders_handle_and_break_only_by_an_operator() -> None:
    table = LeaseTable(run_tag="t")
    a = grant(table, req("app-a", "gaze"))
    b = grant(table, req("app-b", "audio"))
    done, ended = table.release(a.lease_id, "app-a", "", T0)
    assert done.success and ended[0].reason == "released"
    # The public id (from leases/state), even naming its holder: not enough.
    for by in ("app-b", "dashboard", None):
        forged, ended = table.release("L2-t", by, "", T0)
        assert not forged.success and ended == [] and "only its holder" in forged.message
    wrong, _ = table.release("L2-t.not-the-secret", "app-b", "", T0)
    assert not wrong.success and table.counters["forged"] == 4
    broke, ended = table.release("L2-t", "operator-cli", "", T0, operator=True)
    assert broke.success and ended[0].reason == "broken"
    assert ended[0].message == "broken by operator-cli"
    gone, ended = table.release(b.lease_id, "app-b", "", T0)
    assert not gone.success and ended == [] and gone.message == "lease L2-t ended (broken)"
    unknown, _ = table.release("nope", None, "", T0)
    assert not unknown.success and unknown.message == "no lease 'nope'"
    nameless = grant(table, req("app-c"))
    _, ended = table.release(m.public_lease_id(nameless.lease_id), "wizard", "demo over", T0,
                             operator=True)
    assert ended[0].reason == "broken" and ended[0].message == "demo over (by wizard)"


def test_operator_priority_needs_the_operator_credential() -> None:
    table = LeaseTable()
    refused = table.acquire(req("app-x", "expression", priority="operator"), T0, True).reply
    assert not refused.granted and "operator credential" in refused.message
    assert table.counters["operator_refused"] == 1
    assert table.acquire(req("wizard", priority="operator"), T0, True, operator=True).reply.granted


def test_a_gone_holder_loses_only_its_own_instance_leases() -> None:
    table = LeaseTable()
    grant(table, req("app-a", "gaze", instance="old"))
    grant(table, req("app-a", "audio", instance="new"))
    ended = table.holder_gone("app-a", "old", T0)
    assert [e.reason for e in ended] == ["holder_gone"]
    assert ended[0].message == "no liveliness token nodes/app-a/old"
    assert table.held() == ["audio"]
    assert table.holder_gone("app-b", "x", T0) == []


def test_the_ring_keeps_the_last_16_ended() -> None:
    table = LeaseTable(run_tag="t")
    for i in range(ENDED_KEPT + 4):
        lease = grant(table, req(f"app-{i}"))
        table.release(lease.lease_id, f"app-{i}", "", T0 + i)
    snap = table.snapshot(T0)
    assert len(snap.ended) == ENDED_KEPT
    assert snap.ended[0].lease_id == "L5-t" and snap.ended[-1].lease_id == "L20-t"
    assert msgspec.json.decode(msgspec.json.encode(snap), type=m.Leases) == snap  # valid


def fill(table: LeaseTable, n: int, holder: str | None = None) -> None:
    """`n` leases on audio put straight into the table: with three resources no
    real grants reach the limits, which guard against a bug, not a user."""
    for i in range(n):
        table._leases[f"f{i}"] = m.Lease(lease_id=f"f{i}", holder=holder or f"h{i}",
                                         instance="i1", priority="app", resources=["audio"],
                                         granted_ns=T0)


def test_at_most_8_leases_per_holder_instance() -> None:
    table = LeaseTable()
    fill(table, MAX_PER_HOLDER, "app-a")
    over = table.acquire(req("app-a", "expression"), T0, True).reply
    assert not over.granted and over.message == f"app-a already holds {MAX_PER_HOLDER} leases"
    assert table.acquire(req("app-a", "expression", instance="i2"), T0, True).reply.granted


def test_at_most_64_leases_but_preempted_ones_make_room() -> None:
    table = LeaseTable()
    fill(table, MAX_LEASES)
    reply = table.acquire(req("app-new", "gaze"), T0, True).reply
    assert not reply.granted and reply.message == f"too many leases: {MAX_LEASES} held"
    taken = table.acquire(req("wizard", "audio", priority="operator"), T0, True, operator=True)
    assert taken.reply.granted and len(taken.ended) == 1 and len(table) == MAX_LEASES


def test_eyes_commands_need_the_resource_and_are_rate_limited() -> None:
    table = LeaseTable(run_tag="t")
    eyes = grant(table, req("app-a", "expression"))
    ok = table.eyes_command(m.EyesCommand(lease_id=eyes.lease_id, expression=X.ANIMATE_LOVE),
                            T0, 20.0, 2.0)
    assert ok.reply.success and ok.control is None
    assert ok.expression == m.ScreenExpression(stamp_ns=T0, action=X.ANIMATE_LOVE)
    gaze = table.eyes_command(m.EyesCommand(lease_id=eyes.lease_id, yaw=0.2), T0, 20.0, 2.0)
    assert not gaze.reply.success and gaze.reply.message == "lease L1-t does not hold gaze"
    forged = table.eyes_command(m.EyesCommand(lease_id="L1-t", expression=X.EYE_SAD), T0, 20.0,
                                2.0)  # the public id, read from leases/state
    assert not forged.reply.success and forged.expression is None
    assert "only its holder commands" in forged.reply.message
    empty = table.eyes_command(m.EyesCommand(lease_id=eyes.lease_id), T0, 20.0, 2.0)
    assert not empty.reply.success and "nothing to do" in empty.reply.message
    # burst 2: the first took one token, the second goes, the third is refused ...
    assert table.eyes_command(m.EyesCommand(lease_id=eyes.lease_id, expression=X.EYE_GRIN),
                              T0, 20.0, 2.0).reply.success
    limited = table.eyes_command(m.EyesCommand(lease_id=eyes.lease_id,
                                               expression=X.EYE_GRIN), T0, 20.0, 2.0)
    assert not limited.reply.success and limited.expression is None
    assert limited.reply.message.startswith("rate limited")
    # ... until 1/20 s later one token is back
    assert table.eyes_command(m.EyesCommand(lease_id=eyes.lease_id, expression=X.EYE_GRIN),
                              T0 + S // 20, 20.0, 2.0).reply.success
    assert table.counters["rate_limited"] == 1
    assert table.counters["eyes_commands"] == 3
    assert table.counters["eyes_commands_refused"] == 4 and table.counters["forged"] == 1


def test_a_gaze_command_becomes_eye_control() -> None:
    table = LeaseTable()
    lease = grant(table, req("app-a", "gaze"))
    out = table.eyes_command(m.EyesCommand(lease_id=lease.lease_id, pitch=0.1,
                                           target_distance_cm=80.0), T0, 20.0, 40.0)
    assert out.control == m.EyeControl(stamp_ns=T0, yaw=0.0, pitch=0.1, target_distance_cm=80.0)
    assert out.expression is None


def test_a_sustained_flood_gets_the_rate_and_no_more() -> None:
    table = LeaseTable()
    lease = grant(table, req("app-a", "gaze"))
    sent = sum(table.eyes_command(m.EyesCommand(lease_id=lease.lease_id, yaw=0.0),
                                  T0 + i * S // 1000, 20.0, 40.0).reply.success
               for i in range(10_000))  # 1000/s for 10 s
    assert 40 + 20 * 10 - 2 <= sent <= 40 + 20 * 10 + 1
    assert table.counters["rate_limited"] == 10_000 - sent
