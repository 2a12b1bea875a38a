"""Leases: a program's claim on the eyes and the speaker, granted by the eyes driver.

The eyes driver arbitrates (docs/design.md, leases): a request is granted
when every resource asked for is free or held at a lower priority, refused
naming the holder otherwise. A lease is bound to this program's liveliness
token (`nodes/<name>/<zid>`, declared by `Bot`), so it ends when the program
does, however it ends. It can also end from elsewhere: preempted by a higher
priority, broken by an operator, expired: the program learns it from
`leases/state` (`Lease.ended`, `Lease.on_end`).

The wire side (the request's checks, the calls, reading the state) is the
runtime's, shared with every lease holder (`buddybot.runtime.leasing`); here
its errors become the SDK's (`arbiter_errors`) and `LeaseTable` follows
the published state to the leases this program holds.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable, Generator, Iterable, Iterator
from contextlib import contextmanager
from typing import Any, get_args

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing
from buddybot.runtime.node import Node
from buddybot.sdk.actions import ActionLimit
from buddybot.sdk.calls import sdk_errors
from buddybot.sdk.errors import Refused, TimedOut
from buddybot.sdk.watch import Watch, Watchers

log = logging.getLogger("buddybot.sdk")

ARBITER_HINT = "is the eyes driver running? it grants the leases: `buddybot run eyes`"


@contextmanager
def arbiter_errors(service: keys.Service, timeout: float) -> Iterator[None]:
    """A lease call to the eyes driver in the block, its errors as the SDK's:
    Refused with the arbiter's reason, NoService naming the eyes driver."""
    with sdk_errors(service, timeout, hint=ARBITER_HINT):
        try:
            yield
        except leasing.LeaseRefused as exc:
            raise Refused(str(exc)) from None


Parts = tuple[m.Resource, ...]
"""Resources some lease holds, in the contract's order."""


def held_parts(msg: m.Leases) -> Parts:
    """The resources some lease of `msg` holds, each once, in the contract's order."""
    held = {r for lease in msg.leases for r in lease.resources}
    return tuple(r for r in get_args(m.Resource) if r in held)


class Lease:
    """Resources held by this program until `release()`, its end elsewhere, or
    the program's end. A context manager: leaving the block releases it.

    `ended` is None while active, then why it ended: released, expired,
    holder_gone, preempted or broken (`end_message` has the arbiter's text).
    `lease_id` is the public id (as `leases/state` shows it); `handle`, which
    only this program got from the grant, is what commands and releases it:
    whoever has it acts as the holder, so it is never shown or shared."""

    def __init__(self, table: LeaseTable | None, handle: str, resources: tuple[str, ...],
                 priority: str, duration_s: float | None) -> None:
        self._table = table
        self.handle = handle
        self.lease_id = m.public_lease_id(handle)
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
    """The leases this program holds, asked of and followed on the eyes driver."""

    def __init__(self, node: Node, timeout: float, limit: ActionLimit | None = None) -> None:
        self.node = node
        self.timeout = timeout
        self.limit = limit
        """The program's action limit, taken by each `acquire` it asks itself."""
        self._lock = threading.Lock()
        self._held: dict[str, Lease] = {}
        self._seen: set[str] = set()
        """Held leases the published state listed once (absent later = ended)."""
        self._parts: Watchers[Parts] = Watchers("lease")
        self._state = node.subscribe(keys.LEASES, self._on_state, delivery="queue")

    def holding(self, resource: str) -> Lease | None:
        """The active lease of this program that holds `resource`, if any."""
        with self._lock:
            return next((lease for lease in self._held.values() if lease.holds(resource)),
                        None)

    def acquire(self, names: Iterable[str], priority: str = "app",
                duration_s: float | None = None, timeout: float | None = None, *,
                counted: bool = True, credential: str = "") -> Lease:
        """A granted lease; Refused with the arbiter's reason (or "rate
        limited" over the program's action limit), NoService when no eyes driver
        answers, ValueError for a malformed request. `counted=False`: a lease an
        action takes for itself (the action was counted already). Priority
        "operator" needs the robot's operator secret as `credential`."""
        req = leasing.request(self.node, names, priority, duration_s, credential)
        if counted and self.limit is not None:
            self.limit.take("lease")
        limit = self.timeout if timeout is None else timeout
        with arbiter_errors(keys.LEASE_ACQUIRE, limit):
            lease_id = leasing.acquire(self.node, req, limit)
        lease = Lease(self, lease_id, tuple(req.resources), priority, req.duration_s)
        with self._lock:
            self._held[lease.lease_id] = lease
        lease.on_end(self._forget)
        return lease

    def release(self, lease: Lease, timeout: float | None = None) -> None:
        """Ask the eyes driver to end `lease`; it is over here whatever it answers
        (a lease the eyes driver no longer knows has ended already)."""
        limit = self.timeout if timeout is None else timeout
        try:
            with sdk_errors(keys.LEASE_RELEASE, limit, hint=ARBITER_HINT):
                leasing.release(self.node, lease.handle, timeout=limit)
        except leasing.LeaseRefused as exc:
            log.debug("release of lease %s: %s", lease.lease_id, exc)
        finally:
            lease.end("released")

    def _forget(self, lease: Lease) -> None:
        with self._lock:
            self._held.pop(lease.lease_id, None)
            self._seen.discard(lease.lease_id)

    def _on_state(self, msg: m.Leases, _key: str) -> None:
        for lease, reason, message in self.changes(msg):
            lease.end(reason, message)
        self._parts.notify(held_parts(msg))

    def on_held(self, callback: Callable[[Parts], Any]) -> Watch:
        """Call `callback(parts)` with the parts some lease holds, anyone's
        ("expression", "gaze", "audio", in that order), now (once the
        arbiter's state is known) and on every change of `leases/state`, until
        the returned watch or the bot closes: a behaviour that yields learns what
        it does not hold."""
        return self._parts.add(callback)

    def changes(self, msg: m.Leases) -> list[tuple[Lease, str, str]]:
        """(lease, reason, message) for each held lease that `msg` says has ended:
        listed in `ended`, or no longer listed after having been."""
        out: list[tuple[Lease, str, str]] = []
        with self._lock:
            for lease_id, lease in self._held.items():
                end = leasing.ending(msg, lease_id, seen=lease_id in self._seen)
                if end is not None:
                    out.append((lease, *end))
                elif leasing.find(msg, lease_id) is not None:
                    self._seen.add(lease_id)
        return out

    def close(self, timeout: float = 1.0) -> None:
        """Release every lease still held (bounded), then stop following the state."""
        with self._lock:
            held = list(self._held.values())
        for lease in held:
            try:
                lease.release(timeout)
            except Exception as exc:  # the eyes driver may be gone: the token's end ends it
                log.debug("release of lease %s at close: %r", lease.lease_id, exc)
        self._parts.clear()
        self._state.close()
