"""The options and operands several verbs take, each defined once (ros2topic's `api`).

A verb adds them with these helpers, so `--timeout` is always `S` seconds
with its default said the same way, `--json` is a flag, and a KEY or NODE
operand is named and explained alike in every `--help`. They sit in the
runtime, next to `service.add_common_arguments`, so an area's own verb
(`buddybot radar`) takes them as well as the verbs of `buddybot.cli`.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from buddybot.runtime.session import CONNECT_TIMEOUT_S


def add_timeout_argument(parser: argparse.ArgumentParser, default: float | None, what: str,
                         *, connecting: bool = True, kind: Callable[[str], float] = float,
                         metavar: str | None = "S", shown: str | None = None) -> None:
    """`--timeout S`. `what`: what S limits. `connecting`: S bounds connecting to
    the router too (a probe: CONNECT_TIMEOUT_S when not given); `kind` parses
    and checks the value (argparse's one-line error, exit 2, when it refuses).
    `metavar` and `shown` spell S and the default for a verb that talks to no
    router and says them its own way (`buddybot radar`: TIMEOUT, "default 1.0")."""
    lead = "give up after S seconds, connecting included: " if connecting else ""
    if shown is None:
        shown = f"default {default:g} s" if default else (
            f"default: none, but the router must answer within {CONNECT_TIMEOUT_S:g} s")
    parser.add_argument("--timeout", type=kind, default=default, metavar=metavar,
                        help=f"{lead}{what} ({shown})")


def add_answer_timeout(parser: argparse.ArgumentParser) -> None:
    """`--timeout S` of the verbs that ask one node (`param`, `node info`): the
    node's answer only (connecting is a probe's usual CONNECT_TIMEOUT_S)."""
    add_timeout_argument(parser, 5.0, "wait S seconds for the node's answer, then exit 1",
                         connecting=False)


def add_json_argument(parser: argparse.ArgumentParser, what: str = "print JSON") -> None:
    """`--json`: one JSON document on stdout instead of lines for people."""
    parser.add_argument("--json", action="store_true", help=what)


def add_key_argument(parser: argparse.ArgumentParser, *, wildcards: bool = True) -> None:
    """The KEY operand of the probes (`echo`, `hz`, `pub`, `call`); `wildcards`:
    whether the verb takes a key expression (a publication needs one key)."""
    more = "; wildcards allowed" if wildcards else ""
    parser.add_argument("key", help=f"key (prefix buddybot/<robot>/ optional{more})")


def add_node_argument(parser: argparse.ArgumentParser) -> None:
    """The NODE operand of `param` and `node`."""
    parser.add_argument("node", help="node name (see `buddybot nodes`)")
