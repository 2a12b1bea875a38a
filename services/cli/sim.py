"""`buddybot sim list|check`: the simulated world's scenarios, without starting anything.

`list` names the built-in scenarios with what happens in each; `check
NAME|FILE` loads one as `up --sim --scenario` would and says whether it
can run (exit 0), or why not in one line naming the key and the line of
the file (exit 2). See docs/simulation.md for the file format.
"""

from __future__ import annotations

import argparse

from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.runtime.errors import EXIT_OK, UsageError
from buddybot.runtime.service import ServiceContext
from buddybot.sim import scenario

HELP = "the simulated world: list the built-in scenarios, check a scenario file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, dest="op")


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


def _add_list(parser: argparse.ArgumentParser) -> None:
    pass


def _list(ctx: ServiceContext) -> int:
    names = scenario.builtin_names()
    width = max(len(n) for n in names)
    for name in names:
        spec = scenario.load(name).spec
        loop = f"loops every {spec.length_s:g} s" if spec.loop else f"{spec.length_s:g} s once"
        print(f"{name.ljust(width)}  {spec.description} ({loop})")
    return EXIT_OK


def _add_check(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", metavar="NAME|FILE", help="a built-in name or a file")


def _check(ctx: ServiceContext) -> int:
    try:
        found = scenario.load(ctx.args.scenario)
    except scenario.ScenarioError as exc:
        raise UsageError(str(exc)) from None
    spec = found.spec
    print(f"{found.source}: ok: {len(spec.person)} people, {len(spec.clutter)} clutter, "
          f"{spec.length_s:g} s{' on a loop' if spec.loop else ''}")
    return EXIT_OK


SUBVERBS = (
    SubVerb("list", "the built-in scenarios and what happens in each", _add_list, _list),
    SubVerb("check", "load a scenario as `up` would: exit 0, or 2 with the reason",
            _add_check, _check, synopsis="NAME|FILE"),
)
