"""Verbs made of sub-verbs (`param list|get|...`, `bag record|play|info`, `node info`).

Each sub-verb is its own small unit, as in ros2cli's `ros2param/verb/*.py`:
a name, a help line, `add_arguments(parser)` and `main(ctx) -> int`. The verb
module lists them and hands them to `add_subverbs` from its own
`add_arguments`; its `main` is `run`. So argparse checks the operands of
each sub-verb, prints its `--help`, and tab completion offers the sub-verbs'
names and options; no verb counts its operands by hand.

The common options (`--connect`, `--robot`, `--config`, `--log-level`) and
the verb's `shared` options are accepted before the sub-verb and after it
(`bag play FILE --robot other`, `param list NODE --connect E`).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, NoReturn

from buddybot.runtime.service import ServiceContext, add_common_arguments

AddArguments = Callable[[argparse.ArgumentParser], None]


@dataclass(frozen=True)
class SubVerb:
    name: str
    help: str
    add_arguments: AddArguments
    main: Callable[[ServiceContext], int]
    synopsis: str = ""
    """Its operands (`NODE FIELD VALUE`): when given, a missing or extra operand is
    answered by one line, `buddybot VERB: usage: buddybot VERB SUB SYNOPSIS`."""


class SubVerbParser(argparse.ArgumentParser):
    """A sub-verb's parser: argparse's, but wrong operands get the synopsis line."""

    def __init__(self, *args: Any, synopsis: str = "", verb_prog: str = "",
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.synopsis = synopsis
        self.verb_prog = verb_prog

    def parse_known_args(self, args: Iterable[str] | None = None,
                         namespace: Any = None) -> tuple[Any, list[str]]:
        parsed, extra = super().parse_known_args(args, namespace)
        if self.synopsis and any(not word.startswith("-") for word in extra):
            self._usage_line()
        return parsed, extra

    def error(self, message: str) -> NoReturn:
        if self.synopsis and message.startswith("the following arguments are required"):
            self._usage_line()
        super().error(message)

    def _usage_line(self) -> NoReturn:
        self.exit(2, f"{self.verb_prog}: usage: {self.prog} {self.synopsis}\n")


def add_subverbs(parser: argparse.ArgumentParser, subverbs: Sequence[SubVerb], *,
                 dest: str = "action", metavar: str | None = None,
                 shared: AddArguments | None = None) -> None:
    """Register `subverbs` as argparse sub-parsers of the verb's `parser`.

    `dest` and `metavar` name the sub-verb in usage lines and errors
    (`argument op: invalid choice: ...`). `shared` adds the options every
    sub-verb takes, to the verb's parser and to each sub-verb's. In a
    sub-verb's parser the defaults of the common and shared options are
    suppressed, so one given before the sub-verb is not overwritten."""
    if shared is not None:
        shared(parser)
    choices = parser.add_subparsers(dest=dest, metavar=metavar, required=True,
                                    parser_class=SubVerbParser)
    for sub in subverbs:
        child = choices.add_parser(sub.name, help=sub.help, description=sub.help,
                                   synopsis=sub.synopsis, verb_prog=parser.prog)
        accepted = len(child._actions)
        add_common_arguments(child)
        if shared is not None:
            shared(child)
        for action in child._actions[accepted:]:  # not set_defaults: it would store SUPPRESS
            action.default = argparse.SUPPRESS
        sub.add_arguments(child)
        child.set_defaults(subverb_main=sub.main)


def run(ctx: ServiceContext) -> int:
    """The `main` of a verb made of sub-verbs: the chosen sub-verb's."""
    main: Callable[[ServiceContext], int] = ctx.args.subverb_main
    return main(ctx)
