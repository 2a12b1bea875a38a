"""`buddybot doctor`: one line per check (OK/WARN/FAIL), exit 1 if any failed."""

from __future__ import annotations

import argparse
import logging

from buddybot.runtime import options
from buddybot.runtime.service import ServiceContext, add_common_arguments

HELP = "check the robot: config, devices, versions, router, nodes, sensor rates, eyes, clock"
USES_CONFIG = False
"""A broken config is one of the things doctor reports, so run_main must not stop
on it first: doctor loads the config itself (with the common options below)."""


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0 < value <= 60:
        raise argparse.ArgumentTypeError(f"must be in (0, 60] seconds, got {text}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_common_arguments(parser)
    parser.add_argument("--quick", action="store_true",
                        help="only the checks that need no running robot (config, devices, "
                        "versions, router port)")
    parser.add_argument("--sim", action="store_true",
                        help="the robot runs simulated: no radar, camera or audio hardware")
    parser.add_argument("--expect", action="append", metavar="NODE",
                        help="nodes that must be alive (repeatable; default: the services "
                        "and apps the config runs under `up`)")
    options.add_json_argument(parser, "print the checks as JSON")
    options.add_timeout_argument(parser, 3.0, "give up on the router after S seconds",
                                 connecting=False, kind=_positive)
    parser.add_argument("--window", type=_positive, default=2.0, metavar="S",
                        help="measure sensor rates over S seconds (default 2)")


def main(ctx: ServiceContext) -> int:
    from buddybot.runtime import registry
    from buddybot.runtime.config import DEFAULT_ENDPOINT, default_config
    from buddybot.runtime.errors import ConfigError, UsageError
    from buddybot.runtime.service import resolve
    from buddybot.tools import doctor

    args = ctx.args
    # Zenoh's own "unable to connect" warning repeats what the router check says.
    logging.getLogger("zenoh").setLevel(logging.ERROR)
    if args.expect:
        known = {e.name for e in registry.SERVICES}
        unknown = [n for n in args.expect if n not in known]
        if unknown:
            raise UsageError(f"--expect: unknown node {', '.join(unknown)} (known: "
                             f"{', '.join(sorted(known))})")
    config, error = None, None
    try:
        resolved = resolve(args, "doctor")
        config, robot, connect = resolved.config, resolved.robot, resolved.connect
    except ConfigError as exc:
        error = str(exc)
        robot, connect = args.robot or "buddy", args.connect or [DEFAULT_ENDPOINT]
    opts = doctor.Options(
        sim=args.sim, endpoint=connect[0], robot=robot,
        expected=args.expect or doctor.expected_nodes(
            config or default_config(), registry.available_services(), args.sim),
        timeout=args.timeout, window_s=args.window,
        zenoh_file=config.zenoh.config_file if config is not None else None, stop=ctx.stop,
    )
    if args.quick:
        checks = doctor.quick_checks(config, error, opts)
    else:
        checks, live = doctor.bus_checks(config or default_config(), opts)
        checks += doctor.quick_checks(config, error, opts, port=False, in_use=live)
    print(doctor.to_json(checks) if args.json else doctor.format_report(checks), flush=True)
    return doctor.exit_code(checks)
