"""`buddybot lease list|break`: who holds the eyes and the speaker, and ending a lease.

`list` reads the arbiter's latched `leases/state` (every lease now, and
the last ones that ended with their reasons); `break ID` asks the
arbiter in the eyes driver (`leases/release`) to end one, as an operator: the lease ends
`broken` and the built-in behaviour gets the resources back at
once (docs/design.md 4.8).

Exit status: 0 done, 1 no answer within `--timeout` or the lease is unknown
(already ended, or never was), 2 bad usage.
"""

from __future__ import annotations

import argparse
import threading
import time

import msgspec

from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import leasing, options
from buddybot.runtime.errors import NoReplyError, ServiceError, UsageError
from buddybot.runtime.service import ServiceContext

HELP = "list the leases on the eyes and the speaker, or break one"
OPERATOR = "operator-cli"
"""The `by` of `break`: not a holder's name, so the lease ends `broken`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, dest="op", shared=_shared)


def _shared(parser: argparse.ArgumentParser) -> None:
    options.add_answer_timeout(parser)
    options.add_json_argument(parser)


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


def _when(stamp_ns: int) -> str:
    return time.strftime("%H:%M:%S", time.localtime(stamp_ns / 1e9))


def _expires(lease: m.Lease, now_ns: int) -> str:
    if lease.expires_ns is None:
        return "when released"
    return f"in {max(0.0, (lease.expires_ns - now_ns) / 1e9):.0f} s ({_when(lease.expires_ns)})"


def table_lines(state: m.Leases, now_ns: int) -> list[str]:
    """The leases as aligned lines for people, then the recently ended ones."""
    rows = [("LEASE", "HOLDER", "PRIORITY", "RESOURCES", "SINCE", "EXPIRES")]
    rows += [(x.lease_id, x.holder, x.priority, ",".join(x.resources), _when(x.granted_ns),
              _expires(x, now_ns)) for x in state.leases]
    widths = [max(len(r[i]) for r in rows) for i in range(5)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r[:5], widths, strict=True)) + "  " + r[5]
             for r in rows]
    if not state.leases:
        lines = ["no leases: the controller's own behaviour drives the eyes and the speaker"]
    if state.ended:
        lines.append("ended recently:")
        lines += [f"  {e.lease_id}  {e.holder}  {e.reason}  {_when(e.stamp_ns)}"
                  + (f"  {e.message}" if e.message else "") for e in state.ended]
    return lines


def _add_list(_parser: argparse.ArgumentParser) -> None:
    pass


def _list(ctx: ServiceContext) -> int:
    got: list[m.Leases] = []
    arrived = threading.Event()

    def on_state(msg: m.Leases, _key: str) -> None:
        got.append(msg)
        arrived.set()

    with ctx.probe() as node:
        node.subscribe(keys.LEASES, on_state)
        if not arrived.wait(ctx.args.timeout):
            raise ServiceError(
                f"no {keys.LEASES.pattern} within {ctx.args.timeout:g} s "
                "(is the eyes driver running?)")
    state = got[-1]
    if ctx.args.json:
        print(msgspec.json.encode(state).decode())
    else:
        print("\n".join(table_lines(state, m.now_ns())))
    return 0


def _add_break(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("lease_id", metavar="ID", help="the lease (as `lease list` shows it)")
    parser.add_argument("--reason", default="", metavar="TEXT",
                        help="why, kept in leases/state with the ended lease")


def _break(ctx: ServiceContext) -> int:
    lease_id = ctx.args.lease_id
    credential = leasing.operator_credential()
    if not credential:
        raise UsageError("breaking a lease needs the robot's operator secret, and none is "
                         "readable here: `buddybot secret show` makes and prints it (run "
                         "this as the robot's owner)")
    with ctx.probe() as node:
        try:
            text = leasing.release(node, lease_id, ctx.args.reason, ctx.args.timeout,
                                   by=OPERATOR, credential=credential)
        except NoReplyError:
            raise ServiceError(
                f"nobody answered {keys.LEASE_RELEASE.pattern} within {ctx.args.timeout:g} s "
                "(is the eyes driver running?)") from None
    reply = m.TriggerReply(success=True, message=text)
    print(msgspec.json.encode(reply).decode() if ctx.args.json else text)
    return 0


SUBVERBS = (
    SubVerb("list", "every lease now (holder, priority, resources, since, expiry) and the "
            "last ones that ended, with their reasons", _add_list, _list),
    SubVerb("break", "end a lease as an operator (it ends `broken`)", _add_break, _break,
            "ID"),
)
