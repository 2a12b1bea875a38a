"""What `buddybot run SERVICE` hands a service: its options, config and a node.

Common options (`--connect`, `--robot`, `--config`, `--log-level`) are the
same for every service and tool; the effective values combine the command
line (wins), the config file and the defaults.

Under systemd (`Type=notify`, `WatchdogSec=`) the service reports ready once
its node is up, and its node's timer thread sends the watchdog pings: a
process that hangs or stops loses its pings and systemd restarts it, and so
does one whose `alive_checks` fail (a web surface whose listener is gone).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from buddybot.contract.keys import DEFAULT_ROBOT, ID_MAX, valid_robot_id
from buddybot.runtime.config import ConfigBase, default_config, load_config, resolve_path
from buddybot.runtime.errors import (
    EXIT_FAILURE,
    EXIT_OK,
    BuddyBotError,
    ConfigError,
    exit_status,
)
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node, install_signal_handlers
from buddybot.runtime.sdnotify import Notifier
from buddybot.runtime.session import (
    CONNECT_TIMEOUT_S,
    RouterUnreachable,
    route_zenoh_log,
    zenoh_config,
)
from buddybot.runtime.supervised import die_with_supervisor


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("common options")
    group.add_argument(
        "--connect", action="append", metavar="ENDPOINT",
        help="Zenoh router endpoint (repeatable; default from config, else tcp/127.0.0.1:7447)",
    )
    group.add_argument("--robot", metavar="ID", help="robot id: keys are buddybot/<ID>/... "
                       "(default from config, else 'buddy')")
    group.add_argument("--config", metavar="FILE",
                       help="TOML config file (default: $BUDDYBOT_CONFIG)")
    group.add_argument("--log-level", default="INFO",
                       choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                       help="log verbosity, ours and Zenoh's (INFO shows Zenoh's warnings)")


def setup_logging(level: str) -> None:
    """Our log on stderr, with Zenoh's own log routed into it at the same
    level (Zenoh alone would print on stdout, and not at all by default)."""
    logging.basicConfig(
        level=getattr(logging, level),
        format="%(asctime)s.%(msecs)03d %(levelname)-7s %(name)s: %(message)s",
        datefmt="%H:%M:%S",
        stream=sys.stderr,
    )
    # Zenoh's connection-failure lines (its DEBUG) are captured for the
    # "no router" message, but shown only at our DEBUG.
    logging.getLogger("zenoh").setLevel(getattr(logging, level))
    route_zenoh_log(level)


@dataclass
class ServiceContext:
    """Everything a service's `run(ctx)` needs, resolved once."""

    name: str
    args: argparse.Namespace
    config: ConfigBase
    robot: str
    connect: list[str]
    stop: threading.Event = field(default_factory=threading.Event)
    notifier: Notifier = field(default_factory=Notifier.from_env)
    alive_checks: list[Callable[[], bool]] = field(default_factory=list)
    """What must hold for the watchdog to be fed (e.g. a web listener still
    serving): one False and the pings stop, so systemd restarts the service."""

    def alive(self) -> bool:
        return all(check() for check in self.alive_checks)

    def feed_watchdog(self) -> None:
        """One watchdog ping, only while every alive check holds."""
        if self.alive():
            self.notifier.watchdog()

    def node(self, name: str | None = None, **kwargs: object) -> Node:
        """Open this service's node (waits for the router; Ctrl-C aborts).

        Then tell systemd the service is ready, and ping its watchdog from the
        node's own timer thread, which stops with the node.
        """
        node = Node(
            name or self.name, robot=self.robot, connect=self.connect,
            zenoh_config_file=self.config.zenoh.config_file, stop_event=self.stop,
            unique=not self.config.robot.allow_duplicate_nodes,
            **kwargs,  # type: ignore[arg-type]
        )
        notifier = self.notifier
        if notifier.enabled:
            notifier.ready(f"node {node.name} up (robot {self.robot})")
            if notifier.watchdog_s:
                notifier.watchdog()
                node.every(notifier.watchdog_s, self.feed_watchdog, name="watchdog")
        return node

    async def node_in_thread(self) -> Node | None:
        """`node()` for a service whose asyncio loop must keep running meanwhile
        (a web server serving pages before the router is found): opened in a
        thread; None when the service is stopped before a router answered."""
        import asyncio  # only the web services need it: not loaded for the others

        def opener() -> Node | None:
            try:
                return self.node()
            except KeyboardInterrupt:  # stopped while waiting for the router
                return None

        return await asyncio.to_thread(opener)

    def probe(self, timeout: float | None = None, *, visible: bool = False) -> Node:
        """A probe node on the robot's router, or RouterUnreachable (exit 1) when
        none answers within `timeout` (default CONNECT_TIMEOUT_S); Ctrl-C aborts.

        Tools and programs use it: unlike a service they must never hang on a
        missing router, and a probe declares nothing that makes it a node of
        the robot (see `Node(probe=True)`). `visible=True`: the same bounded
        connect, but a node of the robot (token `nodes/<name>/<zid>`,
        diagnostics, node info): a program holding leases needs the token,
        whose end ends its leases."""
        limit = timeout if timeout and timeout > 0 else CONNECT_TIMEOUT_S
        config = zenoh_config(connect=self.connect, base_file=self.config.zenoh.config_file,
                              connect_timeout_s=limit)
        try:
            return Node(self.name, robot=self.robot, connect=self.connect, config=config,
                        stop_event=self.stop, probe=not visible)
        except RouterUnreachable as exc:
            raise RouterUnreachable(f"{exc} (gave up after {limit:g} s)") from None


def resolve(args: argparse.Namespace, name: str) -> ServiceContext:
    """Load config (ConfigError on bad input) and merge the common options."""
    config = load_config(getattr(args, "config", None))
    # `is None`, not `or`: `--robot ""` must be refused below, not replaced by the config's id.
    robot = getattr(args, "robot", None)
    robot = config.robot.id if robot is None else robot
    connect = getattr(args, "connect", None)  # append: None or a non-empty list
    connect = list(config.zenoh.connect) if connect is None else connect
    if not valid_robot_id(robot):
        raise ConfigError(f"--robot: {clip(repr(robot), 80)} is not a valid id "
                          f"(1-{ID_MAX} letters, digits, '-', '_')")
    if config.zenoh.config_file:  # relative to the TOML file, like every path in it
        config.zenoh.config_file = str(resolve_path(config, config.zenoh.config_file))
    if config.zenoh.router_config_file:
        config.zenoh.router_config_file = str(resolve_path(config,
                                                           config.zenoh.router_config_file))
    return ServiceContext(name=name, args=args, config=config, robot=robot, connect=connect)


def run_main(
    name: str, args: argparse.Namespace, main: Callable[[ServiceContext], int | None],
    *, uses_config: bool = True,
) -> int:
    """Run a service's `run(ctx)` or a verb's `main(ctx)`: logging, signals, and
    the one exit policy (`buddybot.runtime.errors.exit_status`).

    A usage or config error prints one line and exits 2; any other of our
    errors (a failed call, no router) prints one line and exits 1; Ctrl-C and
    SIGTERM stop quietly with 0. Anything else is a bug and keeps its traceback.
    `uses_config=False`: the verb never reads the robot's configuration (`keys`,
    `schemas`), so a broken config file cannot stop it.
    """
    if not die_with_supervisor(os.environ):
        print(f"buddybot {name}: the `buddybot up` that started it is gone; not starting",
              file=sys.stderr)
        return EXIT_FAILURE
    setup_logging(getattr(args, "log_level", "INFO"))
    try:
        if uses_config:
            ctx = resolve(args, name)
        else:
            ctx = ServiceContext(name=name, args=args, config=default_config(),
                                 robot=DEFAULT_ROBOT, connect=[])
        install_signal_handlers(ctx.stop)
        return int(main(ctx) or 0)
    except BuddyBotError as exc:
        prefix = "buddybot: config error" if isinstance(exc, ConfigError) else f"buddybot {name}"
        print(f"{prefix}: {exc}", file=sys.stderr)
        return exit_status(exc)
    except KeyboardInterrupt:
        return EXIT_OK
