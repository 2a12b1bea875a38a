"""The holder's side of a lease: the request's checks and reading `leases/state`
(pure), the calls and `LeaseHolder` against a scripted controller (no router)."""

from __future__ import annotations

import logging
import threading
from typing import Any

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing
from buddybot.runtime.errors import BUSY_PREFIX, CallError, NoReplyError, ServiceError
from buddybot.runtime.node import Node

# --- the request and the state (pure) ------------------------------------------------------


def test_eyes_is_expression_and_gaze_and_resources_come_once_in_order() -> None:
    assert leasing.resources(["eyes"]) == ("expression", "gaze")
    assert leasing.resources(["audio", "eyes", "gaze"]) == ("expression", "gaze", "audio")
    for bad, why in (([], "at least one resource"), (["ears"], "unknown resource 'ears'"),
                     ([3], "unknown resource 3")):
        with pytest.raises(ValueError, match=why):
            leasing.resources(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), m.MAX_LEASE_S + 1,
                                 True, "10"])
def test_an_absurd_duration_raises_before_asking(bad: object) -> None:
    with pytest.raises(ValueError, match="duration_s must be"):
        leasing.check_duration(bad)  # type: ignore[arg-type]


def test_durations_and_priorities_that_may_be_asked_for() -> None:
    assert leasing.check_duration(None) is None and leasing.check_duration(2) == 2.0
    assert leasing.check_duration(m.MAX_LEASE_S) == m.MAX_LEASE_S
    assert leasing.check_priority("operator") == "operator"
    with pytest.raises(ValueError, match="priority must be one of app, operator, not 'builtin'"):
        leasing.check_priority("builtin")


def test_a_request_is_this_node_s_and_checked_before_anything_is_sent() -> None:
    ctl = Controller()
    req = leasing.request(ctl, ["audio", "eyes"], "app", 5)  # type: ignore[arg-type]
    assert req == m.LeaseRequest(holder="dashboard", instance="abc123",
                                 resources=["expression", "gaze", "audio"], priority="app",
                                 duration_s=5.0)
    for names, priority, duration, why in ((["eyes"], "builtin", None, "priority"),
                                           (["ears"], "app", None, "unknown resource"),
                                           (["gaze"], "app", float("nan"), "duration_s")):
        with pytest.raises(ValueError, match=why):
            leasing.request(ctl, names, priority, duration)  # type: ignore[arg-type]
    assert ctl.requests == []


def _listed(*ids: str) -> list[m.Lease]:
    return [m.Lease(lease_id=i, holder="app", instance="z", priority="app",
                    resources=["gaze"], granted_ns=1) for i in ids]


def test_the_state_says_a_lease_ended_when_listed_ended_gone_once_seen_or_unlisted_after(
        ) -> None:
    end = m.LeaseEnd(lease_id="C", holder="app", reason="broken", stamp_ns=2,
                     message="broken by wizard")
    state = m.Leases(stamp_ns=100, leases=_listed("A"), ended=[end])
    assert leasing.ending(state, "A", seen=True, asked_ns=50) is None  # listed: holds
    assert leasing.ending(state, "C") == ("broken", "broken by wizard")
    assert leasing.ending(state, "B") is None  # maybe not listed yet
    assert leasing.ending(state, "B", seen=True) == ("ended", leasing.GONE)
    assert leasing.ending(state, "B", asked_ns=100) == ("ended", leasing.NOT_LISTED)
    assert leasing.ending(state, "B", asked_ns=101) is None  # older than the request


# --- the calls, against a scripted controller ----------------------------------------------


class Controller:
    """A node stand-in whose `call` answers as the controller would (scripted)."""

    name = "dashboard"
    instance = "abc123"
    log = logging.getLogger("test.leasing")

    def __init__(self) -> None:
        self.requests: list[tuple[str, Any]] = []
        self.grant = True
        self.absent = False
        self.live: set[str] = set()
        self.lock = threading.Lock()

    def call(self, service: keys.Service, request: Any, *, timeout: float) -> Any:
        assert timeout <= leasing.CALL_TIMEOUT_S
        with self.lock:
            self.requests.append((service.key, request))
            if self.absent:
                raise NoReplyError(service.key, "no reply within 3 s")
            if service is keys.LEASE_ACQUIRE:
                if not self.grant:
                    return m.LeaseReply(granted=False, message="held by greeter (operator)")
                lease_id = f"L{len(self.requests)}"
                self.live.add(lease_id)
                return m.LeaseReply(granted=True, lease_id=lease_id)
            if service is keys.LEASE_RELEASE:
                if request.lease_id not in self.live:
                    return m.TriggerReply(success=False, message="unknown lease")
                self.live.discard(request.lease_id)
                return m.TriggerReply(success=True, message="released")
            assert service is keys.EYES_COMMAND
            if request.lease_id not in self.live:
                return m.TriggerReply(success=False, message=f"{request.lease_id}: no such lease")
            return m.TriggerReply(success=True, message="")


def holder(ctl: Controller) -> leasing.LeaseHolder:
    return leasing.LeaseHolder(ctl, ["expression", "gaze"], "operator")  # type: ignore[arg-type]


def test_acquire_once_command_with_it_and_release() -> None:
    ctl = Controller()
    h = holder(ctl)
    lease_id = h.acquire()
    assert h.acquire() == lease_id  # held: not asked again
    request = ctl.requests[0][1]
    assert (request.holder, request.instance, request.priority) == \
        ("dashboard", "abc123", "operator")
    assert request.resources == ["expression", "gaze"] and request.duration_s is None
    h.command(expression=m.ExpressionAction.EYE_GRIN)
    sent = ctl.requests[-1][1]
    assert sent == m.EyesCommand(lease_id=lease_id, expression=m.ExpressionAction.EYE_GRIN)
    assert h.release("done") == "released"
    assert ctl.requests[-1][1] == m.LeaseRelease(lease_id=lease_id, reason="done",
                                                 by="dashboard")
    assert h.lease_id is None and h.release() is None
    with pytest.raises(leasing.LeaseRefused, match="no lease held"):
        h.command(yaw=0.1, pitch=0.0)


def test_a_lease_for_a_remote_side_is_given_back_once_that_side_is_quiet() -> None:
    ctl = Controller()
    h = holder(ctl)
    assert not h.release_if_idle(100.0, 5.0, "ROS 2 command")  # none held: nothing asked
    assert ctl.requests == []
    lease_id = h.acquire()
    assert not h.release_if_idle(4.9, 5.0, "ROS 2 command") and h.lease_id == lease_id
    ctl.absent = True  # the arbiter does not answer: logged, the handle forgotten
    assert not h.release_if_idle(5.0, 5.0, "ROS 2 command") and h.lease_id is None
    ctl.absent = False
    second = h.acquire()
    assert h.release_if_idle(5.0, 5.0, "ROS 2 command") and h.lease_id is None
    assert ctl.requests[-1][1] == m.LeaseRelease(lease_id=second,
                                                 reason="no ROS 2 command for 5 s",
                                                 by="dashboard")


def test_an_operator_breaks_a_lease_as_someone_else_and_a_refused_command_says_why(
        ) -> None:
    ctl = Controller()
    node: Node = ctl  # type: ignore[assignment]
    lease_id = holder(ctl).acquire()
    assert leasing.release(node, lease_id, "demo over", by="operator-cli") == "released"
    assert ctl.requests[-1][1] == m.LeaseRelease(lease_id=lease_id, reason="demo over",
                                                 by="operator-cli")
    with pytest.raises(leasing.LeaseRefused, match=f"{lease_id}: no such lease"):
        leasing.eyes_command(node, m.EyesCommand(lease_id=lease_id, yaw=0.1), 1.0)


def test_refusals_and_a_missing_controller_are_errors_with_reasons() -> None:
    ctl = Controller()
    ctl.grant = False
    h = holder(ctl)
    with pytest.raises(leasing.LeaseRefused, match="held by greeter"):
        h.acquire()
    assert h.lease_id is None
    ctl.absent = True
    with pytest.raises(ServiceError, match="no reply"):
        h.acquire()
    with pytest.raises(leasing.LeaseRefused, match="unknown lease"):
        ctl.absent = False
        leasing.release(ctl, "L-stale", leasing.BROKEN_BY_OPERATOR)  # type: ignore[arg-type]


def test_a_lease_gone_from_the_state_is_forgotten_but_not_by_an_older_state() -> None:
    ctl = Controller()
    h = holder(ctl)
    before = m.now_ns() - 1_000_000
    lease_id = h.acquire()
    older = m.Leases(stamp_ns=before)  # published before the grant: says nothing yet
    assert not h.forget_unless_in(older) and h.lease_id == lease_id
    listed = m.Leases(stamp_ns=m.now_ns(), leases=[m.Lease(
        lease_id=lease_id, holder="dashboard", instance="abc123", priority="operator",
        resources=["expression"], granted_ns=m.now_ns())])
    assert not h.forget_unless_in(listed)
    assert leasing.find(listed, lease_id) is not None
    assert leasing.find(listed, "other") is None and leasing.find(None, lease_id) is None
    assert h.forget_unless_in(m.Leases(stamp_ns=m.now_ns()))  # broken elsewhere
    assert h.lease_id is None
    assert h.acquire() != lease_id  # the next press takes a new one


class Unseen:
    """A controller that has not seen this node's token for the first `refusals`
    requests, on a clock that only the pauses move."""

    name = "app-new"
    instance = "zid1"

    def __init__(self, refusals: int, message: str = "") -> None:
        self.refusals = refusals
        self.message = message or f"{m.HOLDER_NOT_ALIVE}: no liveliness token nodes/app-new/zid1"
        self.asked = 0
        self.now = 0.0
        self.pauses: list[float] = []

    def call(self, service: keys.Service, request: Any, *, timeout: float) -> Any:
        self.asked += 1
        if self.asked <= self.refusals:
            return m.LeaseReply(granted=False, message=self.message)
        return m.LeaseReply(granted=True, lease_id="L1-x")

    def sleep(self, s: float) -> None:
        self.pauses.append(s)
        self.now += s

    def ask(self, holder: str = "app-new") -> m.LeaseReply:
        req = m.LeaseRequest(holder=holder, instance="zid1", resources=["gaze"])
        return leasing.ask(self, req, clock=lambda: self.now,  # type: ignore[arg-type]
                           sleep=self.sleep)


def test_a_just_started_holder_asks_again_until_its_token_is_seen() -> None:
    ctl = Unseen(refusals=3)
    assert ctl.ask().granted
    assert ctl.asked == 4 and ctl.pauses == [0.02, 0.04, 0.08]


def test_not_alive_is_asked_again_for_a_bounded_time_only() -> None:
    ctl = Unseen(refusals=10**6)
    reply = ctl.ask()
    assert not reply.granted and reply.message.startswith(m.HOLDER_NOT_ALIVE)
    assert ctl.now == pytest.approx(leasing.NOT_ALIVE_WAIT_S)
    assert max(ctl.pauses) == 0.2 and ctl.asked < 20


class Flooded(Unseen):
    """An arbiter whose queue is full for the first `refusals` requests."""

    def call(self, service: keys.Service, request: Any, *, timeout: float) -> Any:
        self.asked += 1
        if self.asked <= self.refusals:
            raise CallError(service.pattern, f"{BUSY_PREFIX}256 requests already waiting")
        return m.LeaseReply(granted=True, lease_id="L1-x")


def test_a_flooded_arbiter_is_asked_again_within_the_timeout_only() -> None:
    passing = Flooded(refusals=3)
    assert passing.ask().granted
    assert passing.asked == 4 and passing.pauses == [0.02, 0.04, 0.08]
    lasting = Flooded(refusals=10**6)
    with pytest.raises(CallError, match="busy"):
        lasting.ask()
    assert lasting.now == pytest.approx(leasing.CALL_TIMEOUT_S) and lasting.asked < 30


def test_other_refusals_and_other_holders_are_answered_at_once() -> None:
    held = Unseen(refusals=1, message="gaze is held by app-a at priority app (lease L1-x)")
    assert not held.ask().granted and held.asked == 1 and held.pauses == []
    other = Unseen(refusals=1)
    assert not other.ask(holder="ghost").granted and other.asked == 1
