"""`buddybot people enrol|list|forget`: who the robot may know by name, with consent.

Every sub-verb asks the identity service (docs/identity.md): `enrol NAME`
remembers the one face in front of the camera now (the explicit act of
consent: nothing is ever enrolled otherwise), `list` shows the enrolled
names with when they were enrolled and last seen (never a template), and
`forget NAME` / `forget --all` erase templates at once; the running
services drop the name from `people/state` as soon as the identity service
clears it.

Exit status: 0 done, 1 refused (no face, two faces, a name that exists,
an unknown name, a declined confirmation) or no identity service answering,
2 bad usage (an empty or too long name, NAME together with `--all`,
`--all` without `--yes` and no terminal to ask on).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import TypeVar

import msgspec

from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import options
from buddybot.runtime.errors import (
    EXIT_FAILURE,
    EXIT_OK,
    NoReplyError,
    ServiceError,
    UsageError,
)
from buddybot.runtime.private_files import operator_secret as operator_credential
from buddybot.runtime.service import ServiceContext
from buddybot.sdk.identity import ENROL_MARGIN_S, checked

HELP = "enrol a face under a name (consent), list the known people, forget them"
NOT_RUNNING = "identity service not running: enable [identity] or `buddybot up --identity`"


Req = TypeVar("Req", bound=m.Message)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, dest="op", shared=_shared)


def _shared(parser: argparse.ArgumentParser) -> None:
    options.add_json_argument(parser)


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


def request(kind: type[Req], **fields: object) -> Req:
    """A request checked against the contract (name 1-64 characters, samples
    1-16, timeout (0, 60] s): UsageError naming what is wrong."""
    try:
        return checked(kind, **fields)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _ask(ctx: ServiceContext, service: keys.Service, req: m.Message,
         timeout: float) -> object:
    with ctx.probe() as node:
        try:
            return node.call(service, req, timeout=timeout)
        except NoReplyError:
            raise ServiceError(NOT_RUNNING) from None


def _print(ctx: ServiceContext, reply: m.Message, text: str) -> None:
    print(msgspec.json.encode(reply).decode() if ctx.args.json else text)


def _done(ok: bool) -> int:
    return EXIT_OK if ok else EXIT_FAILURE


# --- enrol ---------------------------------------------------------------------------------


def _add_enrol(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="the person's name (1-64 characters)")
    parser.add_argument("--samples", type=int, default=5, metavar="N",
                        help="frames of their face to take (1-16, default 5)")
    parser.add_argument("--timeout", dest="collect_s", type=float, default=10.0,
                        metavar="S", help="seconds the camera may take to collect them "
                        "(max 60, default 10); the answer may take 5 s more")
    parser.add_argument("--replace", action="store_true",
                        help="retake an enrolled name (its templates are replaced)")


def _enrol(ctx: ServiceContext) -> int:
    a = ctx.args
    req = request(m.EnrolRequest, name=a.name.strip(), samples=a.samples,
                  timeout_s=a.collect_s, replace=a.replace,
                  credential=operator_credential(), sent_ns=m.now_ns())
    print(f"look at the camera, {req.name} (up to {req.timeout_s:g} s)...", file=sys.stderr)
    reply = _ask(ctx, keys.IDENTITY_ENROL, req, req.timeout_s + ENROL_MARGIN_S)
    assert isinstance(reply, m.EnrolReply)
    text = ((reply.message or f"enrolled {reply.name} ({reply.samples} samples)")
            if reply.success else f"not enrolled: {reply.message}")
    _print(ctx, reply, text)
    return _done(reply.success)


# --- list ----------------------------------------------------------------------------------


def _when(stamp_ns: int | None) -> str:
    if stamp_ns is None:
        return "never"
    return time.strftime("%Y-%m-%d %H:%M", time.localtime(stamp_ns / 1e9))


def table_lines(known: m.KnownPeople) -> list[str]:
    """The enrolled people as aligned lines for people, then the retention rule."""
    if not known.people:
        lines = ["nobody enrolled"]
    else:
        rows = [("NAME", "ENROLLED", "LAST SEEN", "SAMPLES")]
        rows += [(p.name, _when(p.enrolled_ns), _when(p.last_seen_ns), str(p.samples))
                 for p in sorted(known.people, key=lambda p: p.name.casefold())]
        widths = [max(len(r[i]) for r in rows) for i in range(3)]
        lines = ["  ".join(c.ljust(w) for c, w in zip(r[:3], widths, strict=True))
                 + "  " + r[3] for r in rows]
    if known.retention_days is None:
        lines.append("kept until forgotten (no retention limit)")
    else:
        lines.append(f"forgotten after {known.retention_days:g} days unseen")
    return lines


def _add_list(parser: argparse.ArgumentParser) -> None:
    options.add_answer_timeout(parser)


def _list(ctx: ServiceContext) -> int:
    reply = _ask(ctx, keys.IDENTITY_LIST, m.Trigger(), ctx.args.timeout)
    assert isinstance(reply, m.KnownPeople)
    _print(ctx, reply, "\n".join(table_lines(reply)))
    return EXIT_OK


# --- forget --------------------------------------------------------------------------------


def _add_forget(parser: argparse.ArgumentParser) -> None:
    options.add_answer_timeout(parser)
    parser.add_argument("name", metavar="NAME", nargs="?", help="the person to forget")
    parser.add_argument("--all", action="store_true", help="forget everybody")
    parser.add_argument("--yes", action="store_true",
                        help="with --all: do not ask for confirmation")


def _confirmed(ctx: ServiceContext) -> bool:
    """`--all` erases everybody: `--yes`, or a yes typed on the terminal."""
    if ctx.args.yes:
        return True
    if not sys.stdin.isatty():
        raise UsageError("forget --all erases every enrolled face: add --yes to confirm")
    answer = input("forget every enrolled person? [y/N] ")
    return answer.strip().lower() in {"y", "yes"}


def _forget(ctx: ServiceContext) -> int:
    a = ctx.args
    if a.all == (a.name is not None):
        raise UsageError("forget takes NAME or --all (one of the two)")
    if a.yes and not a.all:
        raise UsageError("--yes goes with --all")
    if a.all:
        if not _confirmed(ctx):
            print("nothing forgotten", file=sys.stderr)
            return EXIT_FAILURE
        req = request(m.ForgetRequest, all=True, credential=operator_credential())
    else:
        req = request(m.ForgetRequest, name=a.name.strip(), credential=operator_credential())
    reply = _ask(ctx, keys.IDENTITY_FORGET, req, a.timeout)
    assert isinstance(reply, m.ForgetReply)
    if reply.success:
        text = ("forgot " + ", ".join(reply.forgotten) if reply.forgotten
                else "nobody to forget")
    else:
        text = f"not forgotten: {reply.message}"
    _print(ctx, reply, text)
    return _done(reply.success)


SUBVERBS = (
    SubVerb("enrol", "remember the one face in front of the camera now under NAME "
            "(only with their consent)", _add_enrol, _enrol, "NAME"),
    SubVerb("list", "the enrolled people: name, enrolled, last seen, samples",
            _add_list, _list),
    SubVerb("forget", "erase one person's face templates (NAME) or everybody's (--all)",
            _add_forget, _forget),
)
