"""A Zenoh router in this process: the hub every service connects to."""

from __future__ import annotations

import logging
import threading

import zenoh

from buddybot.core.node import zenoh_config
from buddybot.core.sdnotify import Notifier

log = logging.getLogger("buddybot.router")


def run_router(
    listen: list[str], stop: threading.Event, base_file: str | None = None
) -> None:
    """Serve as a router on `listen` until `stop` is set.

    A Zenoh file that Zenoh cannot parse is a ConfigError (exit status 2, which the
    systemd units do not restart on), naming the file.
    """
    config = zenoh_config(mode="router", listen=listen, base_file=base_file)
    session = zenoh.open(config)
    notifier = Notifier.from_env()  # systemd Type=notify: ready, then watchdog pings
    try:
        log.info("router listening on %s (zid %s)", ", ".join(listen), session.info.zid())
        notifier.ready(f"listening on {', '.join(listen)}")
        while not stop.wait(0.5):
            notifier.watchdog()
    finally:
        notifier.close()
        session.close()
        log.info("router stopped")
