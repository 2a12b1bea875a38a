"""The holder's side of a lease, against a scripted controller (no router)."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing
from buddybot.runtime.errors import NoReplyError, ServiceError


class Controller:
    """A node stand-in whose `call` answers as the controller would (scripted)."""

    name = "dashboard"
    instance = "abc123"

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
