"""Leases: a program's claim on the eyes and the speaker, granted by the controller.

The controller arbitrates (docs/design.md, leases): a request is granted
when every resource asked for is free or held at a lower priority, refused
naming the holder otherwise. A lease is bound to this program's liveliness
token (`nodes/<name>/<zid>`, declared by `Bot`), so it ends when the program
does, however it ends. It can also end from elsewhere: preempted by a higher
priority, broken by an operator, expired: the program learns it from
`leases/state` (`Lease.ended`, `Lease.on_end`).

`resources()` and `check_duration()` are the pure checks made before asking;
`LeaseTable` follows the published state to the leases this program holds.
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
from collections.abc import Callable, Generator, Iterable
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk.calls import call
from buddybot.sdk.errors import Refused, TimedOut

log = logging.getLogger("buddybot.sdk")

RESOURCES: tuple[str, ...] = ("expression", "gaze", "audio")
SHORTHANDS: dict[str, tuple[str, ...]] = {"eyes": ("expression", "gaze")}
"""Names a program may use for several resources at once."""
PRIORITIES: tuple[str, ...] = ("app", "operator")
"""What a program may ask for (`builtin` is the controller's own)."""
CONTROLLER_HINT = "is the controller running? it grants the leases: `buddybot run controller`"


def resources(names: Iterable[str]) -> tuple[str, ...]:
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


def check_priority(priority: str) -> str:
    if priority not in PRIORITIES:
        raise ValueError(f"priority must be one of {', '.join(PRIORITIES)}, "
                         f"not {priority!r}")
    return priority


class Lease:
    """Resources held by this program until `release()`, its end elsewhere, or
    the program's end. A context manager: leaving the block releases it.

    `ended` is None while active, then why it ended: released, expired,
    holder_gone, preempted or broken (`end_message` has the controller's text)."""

    def __init__(self, table: LeaseTable | None, lease_id: str, resources: tuple[str, ...],
                 priority: str, duration_s: float | None) -> None:
        self._table = table
        self.lease_id = lease_id
        self.resources = resources
        self.priority = priority
        self.duration_s = duration_s
        self.ended: str | None = None
        self.end_message = ""
        self._over = threading.Event()
        self._callbacks: list[Callable[[Lease], Any]] = []
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        """Notified when the lease ends, or a handle under it is canceled."""

    @property
    def active(self) -> bool:
        return not self._over.is_set()

    def holds(self, resource: str) -> bool:
        return self.active and resource in self.resources

    def end(self, reason: str, message: str = "") -> bool:
        """Mark the lease over (once); runs the `on_end` callbacks. True the first time."""
        with self._lock:
            if self._over.is_set():
                return False
            self.ended, self.end_message = reason, message
            self._over.set()
            callbacks, self._callbacks = self._callbacks, []
            self._changed.notify_all()
        for callback in callbacks:
            try:
                callback(self)
            except Exception:
                log.exception("on_end callback of lease %s failed", self.lease_id)
        return True

    def on_end(self, callback: Callable[[Lease], Any]) -> None:
        """Call `callback(lease)` once when it ends (at once if it has); from the
        SDK's thread: be quick."""
        with self._lock:
            if not self._over.is_set():
                self._callbacks.append(callback)
                return
        callback(self)

    def wait(self, timeout: float | None = None) -> str:
        """Why it ended, once it has; TimedOut after `timeout` s (None: no limit)."""
        if not self._over.wait(timeout):
            raise TimedOut(f"lease {self.lease_id} on {', '.join(self.resources)} still "
                           f"held after {timeout:g} s")
        return self.ended or ""

    def wait_end(self, timeout: float | None) -> None:
        """Block until it ends, `wake()` is called or `timeout` s pass (for handles)."""
        with self._changed:
            if not self._over.is_set():
                self._changed.wait(timeout)

    def wake(self) -> None:
        """Wake the `wait_end` callers: something they check besides the end changed."""
        with self._changed:
            self._changed.notify_all()

    def release(self, timeout: float | None = None) -> None:
        """End it now (nothing happens when it is over already)."""
        if self.active and self._table is not None:
            self._table.release(self, timeout)

    def __enter__(self) -> Lease:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __await__(self) -> Generator[Any, None, str]:
        return asyncio.to_thread(self.wait).__await__()

    def __repr__(self) -> str:
        state = "active" if self.active else f"ended: {self.ended}"
        return (f"Lease({self.lease_id}, {'+'.join(self.resources)}, {self.priority}, "
                f"{state})")


class LeaseTable:
    """The leases this program holds, asked of and followed on the controller."""

    def __init__(self, node: Node, timeout: float) -> None:
        self.node = node
        self.timeout = timeout
        self._lock = threading.Lock()
        self._held: dict[str, Lease] = {}
        self._seen: set[str] = set()
        """Held leases the published state listed once (absent later = ended)."""
        self._state = node.subscribe(keys.LEASES, self._on_state, delivery="queue")

    def holding(self, resource: str) -> Lease | None:
        """The active lease of this program that holds `resource`, if any."""
        with self._lock:
            return next((lease for lease in self._held.values() if lease.holds(resource)),
                        None)

    def acquire(self, names: Iterable[str], priority: str = "app",
                duration_s: float | None = None, timeout: float | None = None) -> Lease:
        """A granted lease; Refused with the controller's reason, NoService when
        no controller answers, ValueError for a malformed request."""
        wanted = resources(names)
        request = m.LeaseRequest(holder=self.node.name, instance=self.node.instance,
                                 resources=list(wanted),  # type: ignore[arg-type]
                                 priority=check_priority(priority),  # type: ignore[arg-type]
                                 duration_s=check_duration(duration_s))
        limit = self.timeout if timeout is None else timeout
        reply: m.LeaseReply = call(self.node, keys.LEASE_ACQUIRE, request, limit,
                                   hint=CONTROLLER_HINT)
        if not reply.granted:
            raise Refused(reply.message or f"{'+'.join(wanted)} refused")
        lease = Lease(self, reply.lease_id, wanted, priority, request.duration_s)
        with self._lock:
            self._held[lease.lease_id] = lease
        lease.on_end(self._forget)
        return lease

    def release(self, lease: Lease, timeout: float | None = None) -> None:
        """Ask the controller to end `lease`; it is over here whatever it answers
        (a lease the controller no longer knows has ended already)."""
        limit = self.timeout if timeout is None else timeout
        try:
            reply: m.TriggerReply = call(self.node, keys.LEASE_RELEASE,
                                         m.LeaseRelease(lease_id=lease.lease_id,
                                                        by=self.node.name), limit,
                                         hint=CONTROLLER_HINT)
            message = reply.message
        finally:
            lease.end("released")
        if not reply.success:
            log.debug("release of lease %s: %s", lease.lease_id, message)

    def _forget(self, lease: Lease) -> None:
        with self._lock:
            self._held.pop(lease.lease_id, None)
            self._seen.discard(lease.lease_id)

    def _on_state(self, msg: m.Leases, _key: str) -> None:
        for lease, reason, message in self.changes(msg):
            lease.end(reason, message)

    def changes(self, msg: m.Leases) -> list[tuple[Lease, str, str]]:
        """(lease, reason, message) for each held lease that `msg` says has ended:
        listed in `ended`, or no longer listed after having been."""
        ended = {e.lease_id: e for e in msg.ended}
        listed = {lease.lease_id for lease in msg.leases}
        out: list[tuple[Lease, str, str]] = []
        with self._lock:
            for lease_id, lease in self._held.items():
                end = ended.get(lease_id)
                if end is not None and lease_id not in listed:
                    out.append((lease, end.reason, end.message))
                elif lease_id in listed:
                    self._seen.add(lease_id)
                elif lease_id in self._seen:
                    out.append((lease, "ended", "no longer in leases/state"))
        return out

    def close(self, timeout: float = 1.0) -> None:
        """Release every lease still held (bounded), then stop following the state."""
        with self._lock:
            held = list(self._held.values())
        for lease in held:
            try:
                lease.release(timeout)
            except Exception as exc:  # the controller may be gone: the token's end ends it
                log.debug("release of lease %s at close: %r", lease.lease_id, exc)
        self._state.close()
