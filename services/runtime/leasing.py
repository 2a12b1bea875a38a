"""A node's lease on the robot's eyes and speaker, from the holder's side.

The eyes driver arbitrates (docs/design.md section 4.8). This is the
holder's wire side, written once for every holder (the dashboard, Foxglove,
the SDK, `buddybot lease`): the request checked before it leaves, asking,
driving the eyes, giving back, and reading from `leases/state` whether a
lease has ended and why; `LeaseHolder` keeps one lease for a process that
drives the eyes for a person. Every call is bounded by a timeout and raises
`ServiceError` or `LeaseRefused` (with the arbiter's reason): never a hang.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import BUSY_PREFIX, CallError, ServiceError
from buddybot.runtime.node import Node
from buddybot.runtime.private_files import operator_secret

CALL_TIMEOUT_S = 3.0
"""How long a lease call may take before it counts as failed (the arbiter is
local and answers in milliseconds)."""
NOT_ALIVE_WAIT_S = 2.0
"""How long a holder asks again while the arbiter has not seen its liveliness
token (it travels there in milliseconds; seconds only under a heavy load)."""
BROKEN_BY_OPERATOR = "broken by operator"
"""The release reason an operator gives for someone else's lease (the arbiter
records it as `broken`)."""
RESOURCES: tuple[m.Resource, ...] = ("expression", "gaze", "audio")
SHORTHANDS: dict[str, tuple[m.Resource, ...]] = {"eyes": ("expression", "gaze")}
"""Names a request may use for several resources at once."""
PRIORITIES: tuple[m.LeasePriority, ...] = ("app", "operator")
"""What a holder may ask for (`builtin` is the controller's own)."""
GONE = "no longer in leases/state"
"""The end message of a lease that left `leases/state` without an `ended` entry."""
NOT_LISTED = "not in a leases/state newer than its request"
"""The end message of a lease a state newer than its request does not list."""


class LeaseRefused(ServiceError):
    """The arbiter answered no: the text is its reason (who holds what)."""


# --- the request, checked before it leaves (pure) ------------------------------------------


def resources(names: Iterable[str]) -> tuple[m.Resource, ...]:
    """The resources `names` stand for ("eyes" = expression + gaze), in the
    contract's order, once each; ValueError naming the valid ones."""
    wanted: set[str] = set()
    for name in names:
        if not isinstance(name, str) or name not in (*RESOURCES, *SHORTHANDS):
            raise ValueError(f"unknown resource {name!r} (resources: "
                             f"{', '.join((*RESOURCES, *SHORTHANDS))})")
        wanted.update(SHORTHANDS.get(name, (name,)))
    if not wanted:
        raise ValueError(f"a lease needs at least one resource "
                         f"({', '.join((*RESOURCES, *SHORTHANDS))})")
    return tuple(r for r in RESOURCES if r in wanted)


def check_duration(duration_s: float | None) -> float | None:
    """`duration_s` when it is None or a number in (0, MAX_LEASE_S]; ValueError
    otherwise (NaN would go out as JSON null, meaning "forever")."""
    if duration_s is None:
        return None
    if isinstance(duration_s, bool) or not isinstance(duration_s, int | float):
        raise ValueError(f"duration_s must be a number of seconds, not {duration_s!r}")
    if not (math.isfinite(duration_s) and 0 < duration_s <= m.MAX_LEASE_S):
        raise ValueError(f"duration_s must be > 0 and <= {m.MAX_LEASE_S:g} s "
                         f"(None: until released), not {duration_s!r}")
    return float(duration_s)


def check_priority(priority: str) -> m.LeasePriority:
    """`priority` when a holder may ask for it; ValueError naming the valid ones."""
    if priority not in PRIORITIES:
        raise ValueError(f"priority must be one of {', '.join(PRIORITIES)}, "
                         f"not {priority!r}")
    return priority


def request(node: Node, names: Iterable[str], priority: str = "app",
            duration_s: float | None = None, credential: str = "") -> m.LeaseRequest:
    """The checked request of this node (its name and liveliness instance) for
    `names` (see `resources`); ValueError before anything is sent. Priority
    `operator` is granted only with the operator `credential`."""
    return m.LeaseRequest(holder=node.name, instance=node.instance,
                          resources=list(resources(names)),
                          priority=check_priority(priority),
                          duration_s=check_duration(duration_s), credential=credential)


def operator_credential(folder: Path | None = None) -> str:
    """The robot's operator secret from its state folder ("" when there is none):
    what an operator's program (the dashboard, Foxglove, `buddybot lease break`)
    shows the arbiter."""
    return operator_secret(folder)


# --- the calls -----------------------------------------------------------------------------


def ask(node: Node, req: m.LeaseRequest, timeout: float = CALL_TIMEOUT_S, *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep) -> m.LeaseReply:
    """The arbiter's reply to `req`. The arbiter knows live holders from
    its watch of liveliness tokens only, so a program that has just started
    may ask before its own token reached it: that refusal (HOLDER_NOT_ALIVE,
    for a request of this node itself, which is alive) is asked again, with
    a growing pause, for at most NOT_ALIVE_WAIT_S, and a "busy" arbiter (a
    flood filled its queue) within `timeout`; every other answer at once."""
    own = (req.holder, req.instance) == (node.name, node.instance)
    began, pause = clock(), 0.02
    while True:
        try:
            reply: m.LeaseReply = node.call(keys.LEASE_ACQUIRE, req, timeout=timeout)
        except CallError as exc:
            left = began + timeout - clock()
            if not exc.reason.startswith(BUSY_PREFIX) or left <= 0:
                raise
        else:
            left = began + min(NOT_ALIVE_WAIT_S, timeout) - clock()
            if (reply.granted or not own or left <= 0
                    or not reply.message.startswith(m.HOLDER_NOT_ALIVE)):
                return reply
        sleep(min(pause, left))
        pause = min(pause * 2, 0.2)


def acquire(node: Node, req: m.LeaseRequest, timeout: float = CALL_TIMEOUT_S) -> str:
    """Ask for `req` (`ask`); the granted lease's id, LeaseRefused with the
    arbiter's reason otherwise."""
    reply = ask(node, req, timeout)
    if not reply.granted or not reply.lease_id:
        raise LeaseRefused(reply.message or f"{'+'.join(req.resources)} refused")
    return reply.lease_id


def release(node: Node, lease_id: str, reason: str = "",
            timeout: float = CALL_TIMEOUT_S, *, by: str | None = None,
            credential: str = "") -> str:
    """End a lease, asked by this node (or `by`): with its handle (the holder)
    it is `released`; with its public id and the operator `credential` it is
    `broken` (an operator gives BROKEN_BY_OPERATOR). The arbiter's text on
    success, LeaseRefused (unknown, or neither the handle nor an operator)."""
    reply: m.TriggerReply = node.call(
        keys.LEASE_RELEASE,
        m.LeaseRelease(lease_id=lease_id, reason=reason, by=node.name if by is None else by,
                       credential=credential),
        timeout=timeout)
    if not reply.success:
        raise LeaseRefused(reply.message or f"lease {lease_id} not released")
    return reply.message or f"lease {lease_id} ended"


def eyes_command(node: Node, command: m.EyesCommand, timeout: float = CALL_TIMEOUT_S) -> str:
    """Send `command` on `eyes/command`; the arbiter's text, or LeaseRefused
    (the lease does not hold what it drives, has ended, or runs over the rate)."""
    reply: m.TriggerReply = node.call(keys.EYES_COMMAND, command, timeout=timeout)
    if not reply.success:
        raise LeaseRefused(reply.message or f"eyes/command refused on lease {command.lease_id}")
    return reply.message


# --- reading leases/state (pure) -----------------------------------------------------------


def find(state: m.Leases | None, lease_id: str | None) -> m.Lease | None:
    """The lease `lease_id` in a `leases/state` message, if it is still there."""
    if state is None or not lease_id:
        return None
    public = m.public_lease_id(lease_id)
    return next((lease for lease in state.leases if lease.lease_id == public), None)


def ending(state: m.Leases, lease_id: str, *, seen: bool = False,
           asked_ns: int | None = None) -> tuple[str, str] | None:
    """(reason, message) when `state` shows that lease `lease_id` has ended; None
    while it is listed or may not be listed yet.

    Ended: listed in `ended` (the arbiter's reason and text); or not listed
    though an earlier state listed it (`seen`); or not listed in a state
    stamped after the request was sent (`asked_ns`, same clock as the stamp)."""
    if find(state, lease_id) is not None:
        return None
    public = m.public_lease_id(lease_id)
    end = next((e for e in state.ended if e.lease_id == public), None)
    if end is not None:
        return end.reason, end.message
    if seen:
        return "ended", GONE
    if asked_ns is not None and state.stamp_ns >= asked_ns:
        return "ended", NOT_LISTED
    return None


class LeaseHolder:
    """This node's one lease on `resources` at `priority`: at most one at a time.

    Thread-safe (a web server runs each button in a worker thread); the lease's
    handle is kept until released here or seen gone from `leases/state`
    (`forget_unless_in`), so a lease broken elsewhere is not used again. At
    priority `operator` the robot's operator secret is read from the state
    folder at each request (`operator_credential`; `credential` overrides).
    """

    def __init__(self, node: Node, resources: list[m.Resource],
                 priority: m.LeasePriority = "operator",
                 timeout: float = CALL_TIMEOUT_S, credential: str | None = None) -> None:
        self.node = node
        self.resources = resources
        self.priority = priority
        self.timeout = timeout
        self.credential = credential
        self._lock = threading.Lock()
        self.lease_id: str | None = None
        self._asked_ns = 0
        """When the lease was asked for: a `leases/state` older than that may
        not list it yet, and does not end it."""

    def acquire(self, duration_s: float | None = None) -> str:
        """Take the lease (the one already held is kept); its id, or LeaseRefused
        naming who holds what, or ServiceError when the arbiter does not answer."""
        with self._lock:
            if self.lease_id is not None:
                return self.lease_id
            credential = self.credential
            if credential is None:
                credential = operator_credential() if self.priority == "operator" else ""
            req = request(self.node, self.resources, self.priority, duration_s, credential)
            asked_ns = m.now_ns()
            lease_id = acquire(self.node, req, self.timeout)
            self.lease_id, self._asked_ns = lease_id, asked_ns
            return lease_id

    @property
    def public_id(self) -> str | None:
        """The held lease's public id (what `leases/state` and pages may show)."""
        lease_id = self.lease_id
        return None if lease_id is None else m.public_lease_id(lease_id)

    def release(self, reason: str = "") -> str | None:
        """Give the lease back; the arbiter's text, None when none was held.
        The id is forgotten even when the call fails (the arbiter ends the
        lease anyway when this node goes away)."""
        with self._lock:
            lease_id, self.lease_id = self.lease_id, None
        if lease_id is None:
            return None
        return release(self.node, lease_id, reason, self.timeout)

    def release_if_idle(self, quiet_s: float, idle_s: float, side: str) -> bool:
        """Give the lease back once the remote `side` it was taken for ("ROS 2",
        "Foxglove", "dashboard page") has been quiet `idle_s` (`quiet_s` so far):
        the robot's own behaviour returns. True when given back; a failed call is
        logged and, as with `release`, the handle is forgotten all the same."""
        if self.lease_id is None or quiet_s < idle_s:
            return False
        try:
            self.release(f"no {side} for {idle_s:g} s")
        except ServiceError as exc:
            self.node.log.info("idle lease not released: %s", str(exc)[:200])
            return False
        self.node.log.info("%s lease given back: no %s for %g s",
                           "+".join(self.resources), side, idle_s)
        return True

    def forget_unless_in(self, state: m.Leases) -> bool:
        """Drop the id when `leases/state` says the lease ended (see `ending`: gone
        from a state newer than the request, or listed as ended: broken,
        expired); True when it was dropped."""
        with self._lock:
            if self.lease_id is None or ending(state, self.lease_id,
                                               asked_ns=self._asked_ns) is None:
                return False
            self.lease_id = None
            return True

    def command(self, expression: m.ExpressionAction | None = None,
                yaw: float | None = None, pitch: float | None = None,
                target_distance_cm: float = 0.0) -> str:
        """Send `eyes/command` with the lease held; the arbiter's text, or
        LeaseRefused (none held, or the arbiter refused it)."""
        lease_id = self.lease_id
        if lease_id is None:
            raise LeaseRefused("no lease held")
        return eyes_command(self.node, m.EyesCommand(
            lease_id=lease_id, expression=expression, yaw=yaw, pitch=pitch,
            target_distance_cm=target_distance_cm), self.timeout)
