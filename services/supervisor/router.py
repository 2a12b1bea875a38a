"""A Zenoh router in this process: the hub every service connects to."""

from __future__ import annotations

import logging
import threading

import zenoh

from buddybot.runtime import endpoints
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.sdnotify import Notifier
from buddybot.runtime.session import open_router

log = logging.getLogger("buddybot.router")

PROBE_TIMEOUT_S = 1.5
"""How long the look at a taken port may wait for a Zenoh router to answer there
(under the 2 s after which a waiting session logs that it waits)."""


def busy_port(listen: list[str], base_file: str | None = None) -> str | None:
    """The one line saying which of `listen` is taken and by whom, else None.

    The same look as `doctor`'s router-port check (`doctor.port_users`): is it a
    Zenoh router (with whose nodes) or a stranger, and which local process
    holds it when psutil can tell. Only TCP-based endpoints can be looked at.
    """
    for endpoint in listen:
        if not endpoints.accepting(endpoint):
            continue
        from buddybot.tools import doctor  # only for a taken port: slow to load

        zlog = logging.getLogger("zenoh")
        level = zlog.level
        zlog.setLevel(logging.ERROR)  # the probe's own connection noise: not for this line
        try:
            nodes, process = doctor.port_users(endpoint, base_file, PROBE_TIMEOUT_S)
        finally:
            zlog.setLevel(level)
        return (f"cannot listen on {endpoint}: the port is taken by "
                f"{doctor.describe_holder(nodes, process)}; stop it or give --listen "
                "another endpoint")
    return None


def _reason(error: Exception) -> str:
    """Zenoh's error text without its Rust source locations."""
    text = str(error)
    for marker in (" at /", " at src/"):
        text = text.split(marker)[0]
    return text.rstrip(".") or repr(error)


def run_router(
    listen: list[str], stop: threading.Event, base_file: str | None = None
) -> None:
    """Serve as a router on `listen` until `stop` is set.

    A taken port is refused before Zenoh tries it (ServiceError, exit 1, one
    line naming the endpoint and who holds it, see `busy_port`); a port taken
    between that look and the bind, or any other endpoint Zenoh cannot open,
    is one line too. A Zenoh file that Zenoh cannot parse is a ConfigError
    (exit status 2, which the systemd units do not restart on), naming the file.
    """
    busy = busy_port(listen, base_file)
    if busy:
        raise ServiceError(busy)
    try:
        session = open_router(listen, base_file)
    except zenoh.ZError as exc:
        reason = _reason(exc)
        if "in use" in reason:
            raise ServiceError(f"cannot listen on {', '.join(listen)}: the port is taken "
                               f"({reason})") from None
        raise ServiceError(f"cannot start the router on {', '.join(listen)}: "
                           f"{reason}") from None
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
