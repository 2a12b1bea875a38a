"""`buddybot up`: the whole robot on this machine (router on loopback + every service)."""

from __future__ import annotations

import argparse

from buddybot.runtime.config import DEFAULT_ENDPOINT
from buddybot.runtime.service import ServiceContext

HELP = "run the whole robot: router on loopback + every service"


def port_number(text: str) -> int:
    """A TCP port for argparse: 1-65535, else a one-line usage error (exit 2)."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 1-65535, got {port}")
    return port


def add_arguments(parser: argparse.ArgumentParser) -> None:
    for action in parser._actions:  # the common --connect means something more here
        if "--connect" in action.option_strings:
            action.help = ("join the router at ENDPOINT (repeatable) instead of starting "
                           "one; nothing starts if none answers there")
    parser.add_argument("--sim", action="store_true", help="simulated radar and camera")
    parser.add_argument("--scenario", metavar="NAME|FILE",
                        help="the simulated world: a built-in scenario (`buddybot sim list`) or "
                        "a scenario file (default [sim] scenario, else visit)")
    parser.add_argument("--seed", type=int, metavar="N",
                        help="makes the simulated world repeatable (default [sim] seed, else 0)")
    parser.add_argument("--no-browser", action="store_true", help="serve the eye pages only")
    parser.add_argument("--listen", action="append", metavar="ENDPOINT",
                        help="where the router listens (default: the config's [zenoh] connect "
                        f"endpoint when it is on loopback, else {DEFAULT_ENDPOINT}); the "
                        "services use the config's [zenoh] config_file (TLS), the router "
                        "its router_config_file (else config_file). A port already in use "
                        "is refused: nothing starts")
    parser.add_argument("--only", action="append", metavar="SERVICE",
                        help="start only these services (repeatable; an unknown name is an "
                        "error)")
    parser.add_argument("--eye-port", type=port_number, metavar="PORT",
                        help="HTTP port of the eye pages (eye-renderer --port; default "
                        "[eye_renderer] port)")
    parser.add_argument("--dashboard-port", type=port_number, metavar="PORT",
                        help="HTTP port of the dashboard (dashboard --port; default "
                        "[dashboard] port)")
    parser.add_argument("--foxglove", action="store_true",
                        help="also start the Foxglove bridge (`buddybot foxglove`; port "
                        "[foxglove] port)")
    parser.add_argument("--identity", action="store_true",
                        help="also start the identity service (`buddybot run identity`: "
                        "names for enrolled faces; `[identity] enabled = true` does this "
                        "too)")
    parser.add_argument("--ros2", action="store_true",
                        help="also start the ROS 2 bridge (`buddybot run ros2-bridge`; "
                        "domain and namespace from [ros2]; `[ros2] enabled = true` does "
                        "the same)")
    parser.add_argument("--status-period", type=float, default=5.0, metavar="S",
                        help="print a status line every S seconds (0: never)")


def main(ctx: ServiceContext) -> int:
    from buddybot.supervisor.launch import up  # the supervisor: loaded only by this verb

    return up(ctx)
