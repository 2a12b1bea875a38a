"""Zenoh endpoints and local ports: what an endpoint says, and who is on its port.

One reading of a locator (`tcp/127.0.0.1:7447`, `tls/host:port`,
`tcp/[::1]:7447`, with `?...` or `#iface=lo` suffixes) for everything that
must agree on it: `up` choosing and guarding its router's port, `buddybot
router` refusing a taken one, `doctor` judging it, and the web servers (the
dashboard, the Foxglove bridge) naming who holds theirs. The parsing and
classifying functions are pure; `accepting` and `port_holder` are the two
small looks at this machine (a TCP connect, psutil). `Host` and `Port` are
the config fields of a server's address (`[dashboard]`, `[eye_renderer]`,
`[foxglove]`), bounded alike, and so are their flood limits and extra
names (`WebSurface`, which their settings extend).
"""

from __future__ import annotations

import ipaddress
import re
import socket
from dataclasses import dataclass
from typing import Annotated

import msgspec

WILDCARD_HOSTS = frozenset({"", "0.0.0.0", "::", "[::]"})
"""Hosts a server binds to serve every interface (this machine reaches it on loopback)."""
LOCAL_HOST = "127.0.0.1"
"""Where this machine reaches a server bound to a wildcard host."""
TCP_PROTOCOLS = ("tcp", "tls")
"""Zenoh transports over a TCP socket: the only ones a plain connect can look at."""

Host = Annotated[str, msgspec.Meta(max_length=253)]
"""A config field: the address a server binds (a DNS name is at most 253 characters)."""
Port = Annotated[int, msgspec.Meta(ge=0, le=65535)]
"""A config field: a TCP port (0: the system picks a free one, or the field's own meaning)."""
AllowedHosts = Annotated[list[Annotated[str, msgspec.Meta(
    min_length=1, max_length=253, pattern=r"^[A-Za-z0-9._:\[\]%-]+$",
    examples=["buddy.example.org", "192.168.1.20"])]], msgspec.Meta(
    max_length=64, description="names and addresses the service is also served at, "
    "besides loopback, this machine's hostname and the bind address (a request whose "
    "Host is none of them is refused with 421)")]
"""A config field: a web surface's extra names (the web layer's `guard.py`)."""
HeaderTimeout = Annotated[float, msgspec.Meta(
    ge=0.5, le=120.0, description="seconds a client may take to send its request "
    "headers before the connection is cut")]
MaxConnections = Annotated[int, msgspec.Meta(
    ge=1, le=65536, description="client connections held at once at most (kept below "
    "the descriptor limit)")]
MaxPerAddress = Annotated[int, msgspec.Meta(
    ge=1, le=65536, description="client connections held at once from one address")]


class WebSurface(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """The config fields every web surface shares (`[dashboard]`, `[eye_renderer]`,
    `[foxglove]` extend it): the names it is also served at, and its flood
    limits (the web layer's `guard.py` applies them)."""

    # A request for any other name (a DNS-rebinding site's own) gets 421.
    allowed_hosts: AllowedHosts = msgspec.field(default_factory=list)
    # Slow headers are cut; a client over a cap first evicts the oldest
    # connection still sending its headers.
    header_timeout_s: HeaderTimeout = 10.0
    max_connections: MaxConnections = 256
    max_connections_per_address: MaxPerAddress = 64


@dataclass(frozen=True)
class Endpoint:
    """A Zenoh locator taken apart: `proto/host:port` and its suffix (`?...`, `#...`)."""

    proto: str
    host: str
    """Without IPv6 brackets."""
    port: int
    suffix: str = ""

    @property
    def address(self) -> str:
        """`host:port` as a locator or a URL writes it."""
        return join_host_port(self.host, self.port)


def join_host_port(host: str, port: int) -> str:
    """`host:port`, with brackets around an IPv6 host (as URLs and locators write it)."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def parse(endpoint: str) -> Endpoint:
    """Take a locator apart; ValueError when it has no `proto/host:port` form."""
    proto, slash, rest = endpoint.partition("/")
    address, suffix = _split_suffix(rest)
    host, colon, port = address.rpartition(":")
    if not slash or not colon or not port.isdigit():
        raise ValueError(f"not a host:port endpoint: {endpoint!r}")
    return Endpoint(proto, host.strip("[]"), int(port), suffix)


def _split_suffix(text: str) -> tuple[str, str]:
    match = re.search(r"[?#]", text)
    return (text, "") if match is None else (text[:match.start()], text[match.start():])


def is_wildcard(host: str) -> bool:
    return host in WILDCARD_HOSTS


def local_host(host: str) -> str:
    """The host this machine dials to reach a server bound on `host`."""
    return LOCAL_HOST if is_wildcard(host) else host


def is_loopback(host: str) -> bool:
    """Whether `host` (a name or an address, IPv6 with or without brackets) is this
    machine's loopback: `localhost`, all of 127.0.0.0/8, `::1`."""
    h = host.strip("[]").lower().rstrip(".")
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h.split("%")[0]).is_loopback
    except ValueError:
        return False


def endpoint_is_loopback(endpoint: str) -> bool:
    """Whether a locator points at this machine's loopback (False when unparsable)."""
    try:
        return is_loopback(parse(endpoint).host)
    except ValueError:
        return False


def over_tcp(endpoint: str) -> bool:
    """Whether the endpoint's transport runs over TCP (so a plain connect can look)."""
    return endpoint.partition("/")[0] in TCP_PROTOCOLS


def host_port(endpoint: str) -> tuple[str, int]:
    """(host, port) this machine dials for `endpoint` (a wildcard means loopback);
    ValueError when it has none."""
    parsed = parse(endpoint)
    return local_host(parsed.host), parsed.port


def connect_endpoint(listen: str) -> str:
    """Where local services reach a router listening on `listen` (suffix kept)."""
    try:
        parsed = parse(listen)
    except ValueError:
        return listen
    if not is_wildcard(parsed.host):
        return listen
    return f"{parsed.proto}/{LOCAL_HOST}:{parsed.port}{parsed.suffix}"


def accepting(endpoint: str, timeout: float = 0.5) -> bool:
    """Whether something accepts TCP connections on `endpoint` (tcp or tls) right now."""
    if not over_tcp(endpoint):
        return False
    try:
        with socket.create_connection(host_port(endpoint), timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


def port_holder(endpoint: str) -> str | None:
    """The local process listening on `endpoint`'s TCP port ("python3, pid 1234"),
    when psutil can tell: only processes whose sockets we may read (our user's,
    or all as root), and never one on another host. None otherwise."""
    try:
        host, port = host_port(endpoint)
    except ValueError:
        return None
    try:
        import psutil

        conns = psutil.net_connections(kind="tcp")
    except Exception:  # no psutil, or AccessDenied (macOS without root)
        return None
    for conn in conns:
        addr = conn.laddr
        if conn.status != psutil.CONN_LISTEN or not addr or addr.port != port:
            continue
        if addr.ip not in (host, f"::ffff:{host}", "0.0.0.0", "::"):
            continue
        if conn.pid is None:
            return None
        try:
            return f"{psutil.Process(conn.pid).name()}, pid {conn.pid}"
        except psutil.Error:
            return f"pid {conn.pid}"
    return None


def serve_failure(host: str, port: int, error: str) -> str:
    """The one line for a web or WebSocket server that cannot listen (the dashboard,
    the Foxglove bridge); a taken port names its holder and the way out. `error`:
    the OS's or the server library's reason (Foxglove's prefixes are dropped)."""
    reason = error.removeprefix("FoxgloveError: ").removeprefix("Failed to bind port: ")
    reason = re.sub(r" \(os error \d+\)$", "", reason)
    if "in use" not in reason:
        return f"cannot serve on {host}:{port}: {reason}"
    holder = port_holder(f"tcp/{host}:{port}")
    held = f" by {holder}" if holder else ""
    return (f"cannot serve on {host}:{port}: the port is taken{held} ({reason}); stop it "
            "or give --port another port")


def host_names(hostname: str) -> frozenset[str]:
    """The names a machine called `hostname` answers to without DNS: `localhost`,
    the hostname, its first label and that label under `.local` (mDNS)."""
    name = hostname.lower().rstrip(".")
    short = name.split(".")[0]
    return frozenset(n for n in ("localhost", name, short, f"{short}.local") if n)
