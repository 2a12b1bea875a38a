"""The web ports `up` will listen on, checked before anything starts.

The eye renderer, the dashboard and the Foxglove bridge each bind a port of
their own. Found taken only once started, a service exits 2 and is left
down while the rest of the robot runs, and the address `up` would print is
someone else's page. So `up` tries each port first (a bind, as the server
will do it) and refuses in one line naming the port, who holds it and the
setting to change. The addresses `up` prints come from the services' own
"serving" lines (`served_address`), so a service that is not serving has no
address printed. The plan and the texts are pure; `bind_error` is the one
look at this machine.
"""

from __future__ import annotations

import argparse
import errno
import re
import socket
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from buddybot.runtime import endpoints
from buddybot.runtime.config import ConfigBase


@dataclass(frozen=True)
class WebPort:
    """A port a service of `up` listens on, and how a person moves it."""

    service: str
    host: str
    port: int
    setting: str
    """The config key and `up` option that choose it (`[eye_renderer] port or --eye-port`)."""


WEB_SERVICES: tuple[tuple[str, str, str | None], ...] = (
    ("eye-renderer", "eye_renderer", "eye_port"),
    ("dashboard", "dashboard", "dashboard_port"),
    ("foxglove", "foxglove", None),
)
"""(service, its config table, the `up` option that overrides its port)."""

LABELS = {"eye-renderer": "eyes", "dashboard": "dashboard", "foxglove": "foxglove"}
"""How `up` names each service's address when it prints it."""

_SERVING = re.compile(r"\bserving (\S+)")


def planned_ports(config: ConfigBase, args: argparse.Namespace,
                  services: Iterable[str]) -> list[WebPort]:
    """The ports the planned `services` will bind (port 0, any free port, is none)."""
    names = set(services)
    out = []
    for service, table_name, option in WEB_SERVICES:
        table = getattr(config, table_name, None)
        if service not in names or table is None:
            continue
        given = getattr(args, option, None) if option else None
        port = int(given or table.port)
        if port == 0:
            continue
        flag = f" or --{option.replace('_', '-')}" if option else ""
        out.append(WebPort(service, str(table.host), port, f"[{table_name}] port{flag}"))
    return out


def clash(ports: Sequence[WebPort]) -> str | None:
    """The refusal line when two planned services would take one port, else None."""
    seen: dict[int, WebPort] = {}
    for wp in ports:
        other = seen.setdefault(wp.port, wp)
        if other is not wp:
            return (f"buddybot up: {other.service} and {wp.service} would both listen on "
                    f"port {wp.port}: change {wp.setting}. Nothing started.")
    return None


def taken_message(wp: WebPort, holder: str | None) -> str:
    """The one line `up` prints when a service's port is taken (pure)."""
    where = endpoints.join_host_port(wp.host or "0.0.0.0", wp.port)
    by = f" by {holder}" if holder else ""
    return (f"buddybot up: port {where} of the {wp.service} is taken{by}: stop it, or "
            f"change {wp.setting}. Nothing started.")


def served_address(service: str, line: str) -> str | None:
    """`eyes: http://...` from a service's own "... serving URL" line, else None."""
    label = LABELS.get(service)
    match = _SERVING.search(line) if label else None
    return f"{label}: {match.group(1)}" if match else None


def bind_error(host: str, port: int) -> OSError | None:
    """Why a server could not listen on (host, port) now, None when it could: a bind
    with SO_REUSEADDR, as aiohttp binds, so a port left in TIME_WAIT is free."""
    try:
        infos = socket.getaddrinfo(host or None, port, type=socket.SOCK_STREAM,
                                   flags=socket.AI_PASSIVE)
    except OSError as exc:
        return exc
    for family, kind, proto, _name, address in infos:
        with socket.socket(family, kind, proto) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind(address)
            except OSError as exc:
                return exc
    return None


def first_taken(ports: Sequence[WebPort]) -> str | None:
    """The refusal line for the first planned port in use (or a clash), else None.
    Other bind errors (an address not on this host) are left to the service,
    which names them itself."""
    line = clash(ports)
    if line is not None:
        return line
    for wp in ports:
        exc = bind_error(wp.host, wp.port)
        if exc is not None and exc.errno == errno.EADDRINUSE:
            holder = endpoints.port_holder(
                f"tcp/{endpoints.join_host_port(wp.host or '0.0.0.0', wp.port)}")
            return taken_message(wp, holder)
    return None
