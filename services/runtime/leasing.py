"""A node's lease on the robot's eyes and speaker, from the holder's side.

The controller arbitrates (`leases/acquire`, `leases/release`, `eyes/command`,
docs/design.md section 4.8); a lease holder is a node with a liveliness
token, so the controller can end the lease when the holder's process goes
away. `LeaseHolder` is that holder's side for the processes that drive the
eyes for a person (the dashboard's operator switch, Foxglove's expression
service): take the lease, drive the eyes with it, give it back, and know
from `leases/state` whether it still holds. Every call is bounded by a
timeout and raises `ServiceError` (no controller, a bad reply) or
`LeaseRefused` (the controller said no, with its reason): never a hang.
A release names this node (`by`), so the controller tells a holder giving
its lease back (`released`) from an operator breaking someone's (`broken`).
"""

from __future__ import annotations

import threading

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.node import Node

CALL_TIMEOUT_S = 3.0
"""How long a lease call may take before it counts as failed (the controller is
local and answers in milliseconds)."""
BROKEN_BY_OPERATOR = "broken by operator"
"""The release reason an operator gives for someone else's lease (the controller
records it as `broken`)."""


class LeaseRefused(ServiceError):
    """The controller answered no: the text is its reason (who holds what)."""


def find(state: m.Leases | None, lease_id: str | None) -> m.Lease | None:
    """The lease `lease_id` in a `leases/state` message, if it is still there."""
    if state is None or not lease_id:
        return None
    return next((lease for lease in state.leases if lease.lease_id == lease_id), None)


def release(node: Node, lease_id: str, reason: str = "",
            timeout: float = CALL_TIMEOUT_S) -> str:
    """End any lease by id, asked by this node: its own lease is `released`,
    anyone else's `broken` (an operator gives BROKEN_BY_OPERATOR). The
    controller's text on success, LeaseRefused (an unknown id) otherwise."""
    reply: m.TriggerReply = node.call(
        keys.LEASE_RELEASE, m.LeaseRelease(lease_id=lease_id, reason=reason, by=node.name),
        timeout=timeout)
    if not reply.success:
        raise LeaseRefused(reply.message or f"lease {lease_id} not released")
    return reply.message or f"lease {lease_id} ended"


class LeaseHolder:
    """This node's one lease on `resources` at `priority`: at most one at a time.

    Thread-safe (a web server runs each button in a worker thread); the lease
    id is kept until released here or seen gone from `leases/state`
    (`forget_unless_in`), so a lease broken elsewhere is not used again.
    """

    def __init__(self, node: Node, resources: list[m.Resource],
                 priority: m.LeasePriority = "operator",
                 timeout: float = CALL_TIMEOUT_S) -> None:
        self.node = node
        self.resources = resources
        self.priority = priority
        self.timeout = timeout
        self._lock = threading.Lock()
        self.lease_id: str | None = None
        self._asked_ns = 0
        """When the lease was asked for: a `leases/state` older than that may
        not list it yet, and does not end it."""

    def acquire(self, duration_s: float | None = None) -> str:
        """Take the lease (the one already held is kept); its id, or LeaseRefused
        naming who holds what, or ServiceError when the controller does not answer."""
        with self._lock:
            if self.lease_id is not None:
                return self.lease_id
            request = m.LeaseRequest(holder=self.node.name, instance=self.node.instance,
                                     resources=list(self.resources), priority=self.priority,
                                     duration_s=duration_s)
            asked_ns = m.now_ns()
            reply: m.LeaseReply = self.node.call(keys.LEASE_ACQUIRE, request,
                                                 timeout=self.timeout)
            if not reply.granted or not reply.lease_id:
                raise LeaseRefused(reply.message or "refused")
            self.lease_id, self._asked_ns = reply.lease_id, asked_ns
            return reply.lease_id

    def release(self, reason: str = "") -> str | None:
        """Give the lease back; the controller's text, None when none was held.
        The id is forgotten even when the call fails (the controller ends the
        lease anyway when this node goes away)."""
        with self._lock:
            lease_id, self.lease_id = self.lease_id, None
        if lease_id is None:
            return None
        return release(self.node, lease_id, reason, self.timeout)

    def forget_unless_in(self, state: m.Leases) -> bool:
        """Drop the id when a `leases/state` newer than the request no longer
        lists it (ended elsewhere: broken, expired); True when it was dropped."""
        with self._lock:
            if self.lease_id is None or state.stamp_ns < self._asked_ns \
                    or find(state, self.lease_id) is not None:
                return False
            self.lease_id = None
            return True

    def command(self, expression: m.ExpressionAction | None = None,
                yaw: float | None = None, pitch: float | None = None) -> str:
        """Send `eyes/command` with the lease held; the controller's text, or
        LeaseRefused (none held, or the controller refused it)."""
        lease_id = self.lease_id
        if lease_id is None:
            raise LeaseRefused("no lease held")
        reply: m.TriggerReply = self.node.call(
            keys.EYES_COMMAND, m.EyesCommand(lease_id=lease_id, expression=expression,
                                             yaw=yaw, pitch=pitch), timeout=self.timeout)
        if not reply.success:
            raise LeaseRefused(reply.message or "refused")
        return reply.message
