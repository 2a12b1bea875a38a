"""The lease table: who holds the eyes and the speaker, as pure decisions.

The eyes driver hosts the arbiter (`arbiter.py`, docs/design.md 4.8); this
module is its rule book, with no Zenoh and no clock of its own: every method takes `now_ns`
(wall-clock ns, the unit of `expires_ns`) and returns what it decided, so
the service only publishes. The rule:

* a request is granted when every resource it asks for is free or held only
  at a LOWER priority; those lower leases end whole (reason `preempted`);
* it is refused, naming the holder, when any is held at the same or a
  higher priority: first come, first served among equals;
* a lease is a capability: the grant's reply alone carries its handle
  `<public id>.<secret>`; commands and releases need the handle, and
  `leases/state` shows only public ids, so reading the bus lets no one act
  on a lease. An operator (the robot's operator secret as `credential`)
  may break any lease by its public id (`broken`, with who broke it), and
  only an operator may ask for priority `operator`;
* `builtin` (the controller's own behaviour) is never requestable; a
  duration must be finite, > 0 and <= MAX_LEASE_S (None: until released);
  resources may not repeat; the holder must be alive (its liveliness
  token, which the caller knows from its watch of `nodes/*/*`); at most MAX_LEASES leases, at most
  MAX_PER_HOLDER per holder instance.

Each lease also has a token bucket for its actions (`allow`), so an app
looping on eyes commands is slowed down and counted, not obeyed.
"""

from __future__ import annotations

import collections
import hmac
import math
import secrets
from dataclasses import dataclass

from buddybot.contract import messages as m
from buddybot.runtime.rates import TokenBucket

SECRET_BYTES = 16
"""Random bytes of a handle's secret half (22 characters)."""
MAX_LEASES = 64
MAX_PER_HOLDER = 8
ENDED_KEPT = 16
PRIORITY_RANK = {name: rank for rank, name in enumerate(m.LEASE_PRIORITIES)}


@dataclass(frozen=True)
class Eyes:
    """What an eyes command decided: the reply, and what to publish (None: nothing)."""

    reply: m.TriggerReply
    expression: m.ScreenExpression | None
    control: m.EyeControl | None
    pupil: m.PupilControl | None = None
    """A holder's pupil size, instead of the one the distance gives."""


@dataclass(frozen=True)
class Decision:
    """What a request changed: the reply, and the leases it ended (preempted)."""

    reply: m.LeaseReply
    ended: list[m.LeaseEnd]


class LeaseTable:
    """Every lease now and the last ones that ended; single-threaded (the service
    calls it under its lock)."""

    def __init__(self, run_tag: str | None = None) -> None:
        self._tag = run_tag if run_tag is not None else secrets.token_hex(3)
        self._next = 1
        self._leases: dict[str, m.Lease] = {}
        self._secrets: dict[str, str] = {}
        """Public id -> the secret half of its holder's handle."""
        self._buckets: dict[str, TokenBucket] = {}
        self._ended: collections.deque[m.LeaseEnd] = collections.deque(maxlen=ENDED_KEPT)
        self.counters: dict[str, int] = {
            "leases_granted": 0, "leases_refused": 0, "eyes_commands": 0,
            "eyes_commands_refused": 0, "rate_limited": 0, "holders_not_alive": 0,
            "forged": 0, "operator_refused": 0,
        }

    # -- queries --

    def owner(self, resource: m.Resource) -> m.Lease | None:
        for lease in self._leases.values():
            if resource in lease.resources:
                return lease
        return None

    def __len__(self) -> int:
        return len(self._leases)

    def get(self, lease_id: str) -> m.Lease | None:
        return self._leases.get(lease_id)

    def held(self) -> list[m.Resource]:
        """The resources some lease holds now, in the contract's order."""
        taken = {r for lease in self._leases.values() for r in lease.resources}
        return [r for r in ("expression", "gaze", "audio") if r in taken]

    def snapshot(self, now_ns: int) -> m.Leases:
        return m.Leases(stamp_ns=now_ns, leases=list(self._leases.values()),
                        ended=list(self._ended))

    # -- decisions --

    def acquire(self, req: m.LeaseRequest, now_ns: int, holder_alive: bool,
                operator: bool = False) -> Decision:
        """Grant or refuse `req` (see the module's rule); `operator`: its credential
        is the robot's operator secret."""
        problem = self._invalid(req, holder_alive, operator)
        rank = PRIORITY_RANK[req.priority]
        lower: list[m.Lease] = []
        if problem is None:
            for resource in req.resources:
                lease = self.owner(resource)
                if lease is None or lease in lower:
                    continue
                if PRIORITY_RANK[lease.priority] >= rank:
                    problem = (f"{resource} is held by {lease.holder} at priority "
                               f"{lease.priority} (lease {lease.lease_id})")
                    break
                lower.append(lease)
        if problem is None:
            problem = self._over_limits(req, lower)
        if problem is not None:
            self.counters["leases_refused"] += 1
            return Decision(m.LeaseReply(granted=False, message=problem), [])
        ended = [self._end(lease.lease_id, "preempted", now_ns,
                           f"taken by {req.holder} at priority {req.priority}")
                 for lease in lower]
        lease_id = f"L{self._next}-{self._tag}"
        self._next += 1
        expires = (None if req.duration_s is None
                   else now_ns + round(req.duration_s * 1e9))
        self._leases[lease_id] = m.Lease(
            lease_id=lease_id, holder=req.holder, instance=req.instance,
            priority=req.priority, resources=list(req.resources), granted_ns=now_ns,
            expires_ns=expires)
        self._secrets[lease_id] = secrets.token_urlsafe(SECRET_BYTES)
        self.counters["leases_granted"] += 1
        message = ("took over " + ", ".join(f"{e.lease_id} ({e.holder})" for e in ended)
                   if ended else "")
        return Decision(m.LeaseReply(granted=True, lease_id=self.handle(lease_id),
                                     message=message, expires_ns=expires), ended)

    def handle(self, lease_id: str) -> str:
        """The holder's handle of the lease `lease_id` (what its grant returned)."""
        return f"{lease_id}.{self._secrets[lease_id]}"

    def release(self, given: str, by: str | None, reason: str, now_ns: int,
                operator: bool = False) -> tuple[m.TriggerReply, list[m.LeaseEnd]]:
        """End a lease: `released` by its holder (the handle), `broken` by an
        operator (`operator`: the credential held; the public id is enough);
        refused, and counted as forged, for anyone else."""
        lease, holder = self._resolve(given)
        if lease is None:
            return _refuse(self._gone(m.public_lease_id(given))), []
        if not holder and not operator:
            self.counters["forged"] += 1
            return _refuse(f"lease {lease.lease_id}: only its holder (the handle its grant "
                           "returned) or an operator (the operator secret) ends it"), []
        how: m.LeaseEndReason = "released" if holder else "broken"
        text = reason or (f"broken by {by}" if how == "broken" and by else "")
        if how == "broken" and by and by not in text:
            text = f"{text} (by {by})"
        end = self._end(lease.lease_id, how, now_ns, text)
        return m.TriggerReply(success=True, message=f"{lease.lease_id} {how}"), [end]

    def expire(self, now_ns: int) -> list[m.LeaseEnd]:
        due = [lease.lease_id for lease in self._leases.values()
               if lease.expires_ns is not None and lease.expires_ns <= now_ns]
        return [self._end(lease_id, "expired", now_ns, "") for lease_id in due]

    def holder_gone(self, holder: str, instance: str, now_ns: int) -> list[m.LeaseEnd]:
        """The liveliness token `nodes/<holder>/<instance>` went away."""
        gone = [lease.lease_id for lease in self._leases.values()
                if lease.holder == holder and lease.instance == instance]
        return [self._end(lease_id, "holder_gone", now_ns,
                          f"no liveliness token nodes/{holder}/{instance}")
                for lease_id in gone]

    def allow(self, lease_id: str, now_ns: int, rate_per_s: float, burst: float) -> bool:
        """Take one action token of the lease's bucket (`rate_per_s` refill, `burst`
        deep); False (and counted) when it is empty."""
        now_s = now_ns / 1e9
        bucket = self._buckets.get(lease_id)
        if bucket is None:
            bucket = self._buckets[lease_id] = TokenBucket(rate_per_s, burst, now_s)
        bucket.rate_per_s, bucket.burst = rate_per_s, burst
        if bucket.take(now_s):
            return True
        self.counters["rate_limited"] += 1
        return False

    def eyes_command(self, cmd: m.EyesCommand, now_ns: int, rate_per_s: float,
                     burst: float) -> Eyes:
        """What `eyes/command` publishes: the expression if the lease holds
        `expression`, the gaze (yaw/pitch, a missing one 0) and the pupil size
        if it holds `gaze`;
        refused with the reason otherwise, or when the lease's actions run over
        the rate (the bucket of `allow`)."""
        reply, expression, control = self._eyes(cmd, now_ns, rate_per_s, burst)
        self.counters["eyes_commands" if reply.success else "eyes_commands_refused"] += 1
        pupil = (m.PupilControl(stamp_ns=now_ns, dilation_percentage=cmd.pupil_percent)
                 if reply.success and cmd.pupil_percent is not None else None)
        return Eyes(reply, expression, control, pupil)

    def _eyes(self, cmd: m.EyesCommand, now_ns: int, rate_per_s: float, burst: float
              ) -> tuple[m.TriggerReply, m.ScreenExpression | None, m.EyeControl | None]:
        lease, holder = self._resolve(cmd.lease_id)
        if lease is None:
            return _refuse(self._gone(m.public_lease_id(cmd.lease_id))), None, None
        if not holder:
            self.counters["forged"] += 1
            return (_refuse(f"lease {lease.lease_id}: only its holder commands with it (the "
                            "handle its grant returned)"), None, None)
        turn = cmd.yaw is not None or cmd.pitch is not None
        gaze = turn or cmd.pupil_percent is not None
        if cmd.expression is None and not gaze:
            return (_refuse("nothing to do: give an expression, a gaze (yaw, pitch) or a "
                            "pupil size"), None, None)
        asked = [r for r, wanted in (("expression", cmd.expression is not None),
                                     ("gaze", gaze)) if wanted]
        missing = [r for r in asked if r not in lease.resources]
        if missing:
            return (_refuse(f"lease {lease.lease_id} does not hold {', '.join(missing)}"),
                    None, None)
        if not self.allow(lease.lease_id, now_ns, rate_per_s, burst):
            return (_refuse(f"rate limited: more than {rate_per_s:g} eyes commands/s "
                            f"(burst {burst:g}) on lease {lease.lease_id}"), None, None)
        expression = (None if cmd.expression is None
                      else m.ScreenExpression(stamp_ns=now_ns, action=cmd.expression))
        control = (m.EyeControl(stamp_ns=now_ns, yaw=cmd.yaw or 0.0, pitch=cmd.pitch or 0.0,
                                target_distance_cm=cmd.target_distance_cm) if turn else None)
        return m.TriggerReply(success=True), expression, control

    # -- internals --

    def _resolve(self, given: str) -> tuple[m.Lease | None, bool]:
        """(the lease `given` names, whether `given` is its holder's handle)."""
        lease_id, _, secret = given.partition(".")
        lease = self._leases.get(lease_id)
        if lease is None:
            return None, False
        return lease, bool(secret) and hmac.compare_digest(secret, self._secrets[lease_id])

    def _gone(self, lease_id: str) -> str:
        """Why `lease_id` is no lease: it ended (and how, if still remembered) or never was."""
        for end in reversed(self._ended):
            if end.lease_id == lease_id:
                return f"lease {lease_id} ended ({end.reason})"
        return f"no lease {lease_id!r}"

    def _invalid(self, req: m.LeaseRequest, holder_alive: bool, operator: bool) -> str | None:
        if req.priority == "builtin":
            return "priority builtin is the controller's own behaviour: not requestable"
        if req.priority == "operator" and not operator:
            self.counters["operator_refused"] += 1
            return ("priority operator needs the operator credential (the robot's operator "
                    "secret: the dashboard's login, `buddybot secret show`)")
        if len(set(req.resources)) != len(req.resources):
            return f"resources repeat: {req.resources}"
        d = req.duration_s
        if d is not None and not (math.isfinite(d) and 0 < d <= m.MAX_LEASE_S):
            return f"duration_s {d} must be > 0 and <= {m.MAX_LEASE_S:g} (or none)"
        if not holder_alive:
            self.counters["holders_not_alive"] += 1
            return (f"{m.HOLDER_NOT_ALIVE}: no liveliness token "
                    f"nodes/{req.holder}/{req.instance}")
        return None

    def _over_limits(self, req: m.LeaseRequest, lower: list[m.Lease]) -> str | None:
        staying = [lease for lease in self._leases.values() if lease not in lower]
        if len(staying) >= MAX_LEASES:
            return f"too many leases: {MAX_LEASES} held"
        mine = sum(1 for lease in staying
                   if lease.holder == req.holder and lease.instance == req.instance)
        if mine >= MAX_PER_HOLDER:
            return f"{req.holder} already holds {MAX_PER_HOLDER} leases"
        return None

    def _end(self, lease_id: str, reason: m.LeaseEndReason, now_ns: int,
             message: str) -> m.LeaseEnd:
        lease = self._leases.pop(lease_id)
        self._secrets.pop(lease_id, None)
        self._buckets.pop(lease_id, None)
        end = m.LeaseEnd(lease_id=lease_id, holder=lease.holder,
                         reason=reason,
                         stamp_ns=now_ns, message=message[:4096])
        self._ended.append(end)
        return end


def _refuse(message: str) -> m.TriggerReply:
    return m.TriggerReply(success=False, message=message)
