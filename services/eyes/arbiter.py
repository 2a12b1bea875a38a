"""The arbiter: who commands the expression, the gaze and the speaker.

It lives on the actuator side, in the eyes driver, apart from any
behaviour: the built-in behaviour's wishes (`controller/expression`,
`controller/eye_control`) and the lease holders' `eyes/command` meet here,
and what wins is put on `eyes/expression` and `eyes/control` (the one
publisher of each) and handed to the driver. The lease services
(`leases/acquire`, `leases/release`) and `leases/state` are answered from
one liveliness view of the holders; `leases.LeaseTable` is the rule book.
Why here and not in the controller: docs/design.md 4.8.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.eyes.leases import LeaseTable
from buddybot.runtime.node import Node, RateLimitedLog
from buddybot.runtime.private_files import is_operator

log = logging.getLogger("buddybot.eyes")

ACQUIRE_QUEUE = 256
"""Pending `leases/acquire` requests kept: each is answered in microseconds
(no call out), so a flood waits briefly instead of being shed."""
EXPIRE_S = 0.05
"""How often leases are checked for expiry."""

AHEAD = m.EyeControl(stamp_ns=0, yaw=0.0, pitch=0.0, target_distance_cm=0.0)
"""The gaze given back when the built-in behaviour has wished none yet."""

Show = Callable[[m.ScreenExpression | None, m.EyeControl | None, m.PupilControl | None],
               None]
"""What the driver does with a winner (its lids, direction and pupil); the
pupil, when given, instead of the one the gaze's distance gives."""


class Arbiter:
    """One per eyes driver; `start()` declares everything, the node's close ends it."""

    def __init__(self, node: Node, show: Show, rate_per_s: float, burst: float,
                 wall_ns: Callable[[], int] = m.now_ns) -> None:
        self.node = node
        self.show = show
        self.rate_per_s = rate_per_s
        self.burst = burst
        self.wall_ns = wall_ns
        """Wall-clock ns, the clock of lease grants and expiries."""
        self.leases = LeaseTable()
        self._alive: set[tuple[str, str]] = set()
        """(node, instance) of every liveliness token seen alive."""
        self._builtin_expression: m.ScreenExpression | None = None
        self._builtin_control: m.EyeControl | None = None
        self._lock = threading.Lock()
        """Guards the table, the built-in wishes and the publishers' order."""
        self._warn = RateLimitedLog(log)
        self._expression_pub = node.publisher(keys.EXPRESSION)
        self._control_pub = node.publisher(keys.EYE_CONTROL)
        self._leases_pub = node.publisher(keys.LEASES)

    def set_rates(self, rate_per_s: float, burst: float) -> None:
        """A live change of the per-lease action budget."""
        with self._lock:
            self.rate_per_s, self.burst = rate_per_s, burst

    def start(self) -> None:
        node = self.node
        node.watch_nodes(self.on_token)
        with self._lock:
            self._leases_pub.put(self.leases.snapshot(self.wall_ns()))
        # Inline: the built-in gaze is the latency path (camera -> eyes).
        node.subscribe(keys.BEHAVIOUR_EXPRESSION, self.builtin_expression, delivery="inline")
        node.subscribe(keys.BEHAVIOUR_GAZE, self.builtin_control, delivery="inline")
        node.serve(keys.LEASE_ACQUIRE, self.acquire, queue_size=ACQUIRE_QUEUE)
        node.serve(keys.LEASE_RELEASE, self.release)
        node.serve(keys.EYES_COMMAND, self.eyes_command)
        node.every(EXPIRE_S, self.expire, "leases")

    # -- the built-in behaviour --

    def builtin_expression(self, msg: m.ScreenExpression, _key: str = "") -> None:
        with self._lock:
            self._builtin_expression = msg
            if "expression" in self.leases.held():
                log.info("expression %s held back: a lease holds the eyes", msg.action.name)
                return
            self._put(msg, None)

    def builtin_control(self, msg: m.EyeControl, _key: str = "") -> None:
        with self._lock:
            self._builtin_control = msg
            if "gaze" not in self.leases.held():
                self._put(None, msg)

    # -- lease holders --

    def on_token(self, node: str, instance: str, alive: bool) -> None:
        """A liveliness token came or went (Zenoh's thread): a holder that went
        away loses its leases at once."""
        with self._lock:
            if alive:
                self._alive.add((node, instance))
                return
            self._alive.discard((node, instance))
            before = self.leases.held()
            if self.leases.holder_gone(node, instance, self.wall_ns()):
                self._changed(before)

    def acquire(self, req: m.LeaseRequest) -> m.LeaseReply:
        """Grant or refuse at once: whether the holder is alive is read from the
        watch of `nodes/*/*` (`on_token`), never asked per request, so a flood
        of invented holders costs each a set lookup; a program whose token has
        not arrived yet retries (leasing.ask)."""
        operator = self.operator(req.credential)  # a file read: outside the lock
        with self._lock:
            alive = (req.holder, req.instance) in self._alive
            before = self.leases.held()
            decision = self.leases.acquire(req, self.wall_ns(), alive, operator)
            if decision.reply.granted:
                log.info("lease %s granted to %s (%s, %s)", decision.reply.lease_id,
                         req.holder, req.priority, ", ".join(req.resources))
                self._changed(before)
            else:
                self._warn.warning("lease_refused", "lease refused to %s: %s", req.holder,
                                   decision.reply.message)
        return decision.reply

    def release(self, req: m.LeaseRelease) -> m.TriggerReply:
        operator = self.operator(req.credential)
        with self._lock:
            before = self.leases.held()
            reply, ended = self.leases.release(req.lease_id, req.by, req.reason, self.wall_ns(),
                                               operator)
            if ended:
                log.info("lease %s", reply.message)
                self._changed(before)
        return reply

    def eyes_command(self, cmd: m.EyesCommand) -> m.TriggerReply:
        with self._lock:
            eyes = self.leases.eyes_command(cmd, self.wall_ns(), self.rate_per_s, self.burst)
            self._put(eyes.expression, eyes.control, eyes.pupil)
        if not eyes.reply.success:
            # One topic for all: a lease id is the caller's text, and a topic per id
            # would grow the log's table with every invented one.
            self._warn.warning("eyes_refused", "eyes command refused: %s", eyes.reply.message)
        return eyes.reply

    def expire(self) -> None:
        with self._lock:
            before = self.leases.held()
            if self.leases.expire(self.wall_ns()):
                self._changed(before)

    @staticmethod
    def operator(credential: str) -> bool:
        """Whether `credential` is the robot's operator secret (its state folder's)."""
        return is_operator(credential)

    @property
    def counters(self) -> dict[str, int]:
        with self._lock:
            return {**self.leases.counters, "leases": len(self.leases)}

    # -- internals (under the lock) --

    def _changed(self, before: list[m.Resource]) -> None:
        """After the table changed: put `leases/state`, and give the built-in
        behaviour back at once what no lease holds any more."""
        self._leases_pub.put(self.leases.snapshot(self.wall_ns()))
        freed = set(before) - set(self.leases.held())
        now_ns = m.now_ns()
        expression = control = None
        if "expression" in freed and self._builtin_expression is not None:
            expression = msgspec.structs.replace(self._builtin_expression, stamp_ns=now_ns)
        if "gaze" in freed:  # ahead (distance unknown) until the behaviour wishes a gaze
            control = msgspec.structs.replace(self._builtin_control or AHEAD, stamp_ns=now_ns)
        if expression is not None:
            log.info("expression resumed -> %s", expression.action.name)
        self._put(expression, control)

    def _put(self, expression: m.ScreenExpression | None, control: m.EyeControl | None,
             pupil: m.PupilControl | None = None) -> None:
        if expression is not None:
            self._expression_pub.put(expression)
        if control is not None:
            self._control_pub.put(control)
        if expression is not None or control is not None or pupil is not None:
            self.show(expression, control, pupil)
