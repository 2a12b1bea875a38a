"""Who may reach a web surface, and how many: the rules every HTTP/WebSocket server shares.

The dashboard, the eye renderer and the Foxglove bridge's gate answer only
at the names they are served at (`HostAllowList`, `origin_allowed`) and
survive floods (`ConnectionTable`, `pick_eviction`, `AcceptErrorLog`).
The rules are pure, tested without sockets; `GuardedSite` and
`ListenerWatch` apply them to a listening socket. Why each rule is so:
docs/architecture.md, "The web layer".
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import resource
import socket
import ssl
import time
from collections.abc import Awaitable, Callable, Collection, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar
from urllib.parse import urlsplit

from aiohttp import web

from buddybot.runtime.diagnostics import RateLimitedLog
from buddybot.runtime.endpoints import WebSurface, host_names, is_wildcard
from buddybot.runtime.limits import clip

log = logging.getLogger("buddybot.web")

ANONYMOUS = 0
"""The priority of a page nobody vouched for (no login yet)."""
IDLE_S = 30.0
"""A page that sent nothing for this long is idle (eye pages ping every few seconds)."""
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}
DESCRIPTOR_RESERVE = 64
"""Descriptors kept free of client connections (files, Zenoh, logs): at least this many."""


# --- names ---------------------------------------------------------------------------


def _normal(host: str) -> str:
    return host.strip().strip("[]").lower().rstrip(".")


def split_host(value: str | None) -> tuple[str, int | None] | None:
    """(host, port or None) of a `Host` header value or a URL's netloc, lower-case,
    without IPv6 brackets; None when it is not one (garbage, user info)."""
    if value is None:
        return None
    try:
        parts = urlsplit(f"//{value.strip()}")
        port = parts.port
    except ValueError:
        return None
    if not parts.hostname or parts.username is not None or parts.password is not None:
        return None
    return _normal(parts.hostname), port


def local_addresses() -> list[str]:
    """This machine's interface addresses (for a server bound to every interface)."""
    try:
        import psutil

        return [a.address.split("%")[0] for addrs in psutil.net_if_addrs().values()
                for a in addrs if a.family in (socket.AF_INET, socket.AF_INET6)]
    except Exception:  # no psutil, or no permission: names still work
        return []


@dataclass(frozen=True)
class HostAllowList:
    """The names and addresses a service is served at (lower-case, no brackets)."""

    names: frozenset[str]

    @classmethod
    def make(cls, bind_host: str, configured: Iterable[str] = (),
             hostname: str | None = None,
             addresses: Iterable[str] | None = None) -> HostAllowList:
        """Loopback, this machine's names (`hostname`, its short name, `.local`),
        the bind address (every interface address when it is a wildcard) and
        `configured`."""
        hostname = socket.gethostname() if hostname is None else hostname
        names = {*LOOPBACK_NAMES, *host_names(hostname), *(_normal(c) for c in configured)}
        if is_wildcard(bind_host):
            names.update(_normal(a) for a in (local_addresses() if addresses is None
                                              else addresses))
        else:
            names.add(_normal(bind_host))
        return cls(frozenset(n for n in names if n))

    def reached_at(self, local_address: str | None) -> HostAllowList:
        """These names plus the address the connection came in on (an address an
        interface got after start, e.g. from DHCP, names this machine too; a
        rebinding site can only send a DNS name, never our address)."""
        if not local_address or _normal(local_address) in self.names:
            return self
        return HostAllowList(self.names | {_normal(local_address.split("%")[0])})

    def allows(self, host_header: str | None) -> bool:
        """Whether a request's `Host` names this service (no Host: HTTP/1.0, a
        program; it names nothing a browser could be tricked into)."""
        if host_header is None:
            return True
        parsed = split_host(host_header)
        return parsed is not None and parsed[0] in self.names


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _origin_key(origin: str) -> tuple[str, str, int] | None:
    """(scheme, host, port) of an http(s) origin, the port spelled out; None
    for anything else (a path, user info, garbage)."""
    try:
        parts = urlsplit(origin.strip())
    except ValueError:
        return None
    scheme = parts.scheme.lower()
    if scheme not in ("http", "https") or parts.path not in ("", "/") or parts.query:
        return None
    parsed = split_host(parts.netloc)
    if parsed is None:
        return None
    return scheme, parsed[0], parsed[1] or DEFAULT_PORTS[scheme]


def origin_allowed(origin: str | None, hosts: HostAllowList | None, *,
                   port: int | None = None, listed: Collection[str] = (),
                   loopback_any_port: bool = False) -> bool:
    """Whether a browser page from `origin` may open the WebSocket.

    No Origin: a program, not a browser page (it could open any socket
    anyway): allowed. Listed (`listed`, e.g. the Foxglove app's origin, the
    port spelled out or not; "null" or "file://" only when listed
    verbatim): allowed. Else an http(s) origin whose host is in `hosts`
    and whose port is `port` (the port the request came to; None: any), or
    with `loopback_any_port` any page from this machine's loopback. Never
    compared with the request's own Host, which a rebinding site chooses."""
    if origin is None:
        return True
    origin = origin.strip()
    if origin in listed:
        return True
    key = _origin_key(origin)
    if key is None:
        return False
    if any(_origin_key(entry) == key for entry in listed):
        return True
    _scheme, name, origin_port = key
    if loopback_any_port and _is_loopback(name):
        return True
    if hosts is None or name not in hosts.names:
        return False
    return port is None or origin_port == port


def request_port(host_header: str | None, scheme: str = "http") -> int | None:
    """The port a browser addressed (from its Host header; the scheme's default
    when it names none); None without a usable Host."""
    parsed = split_host(host_header)
    if parsed is None:
        return None
    return parsed[1] or DEFAULT_PORTS[scheme]


# --- connections -----------------------------------------------------------------------


def descriptor_budget(wanted: int, reserve: int = DESCRIPTOR_RESERVE,
                      per_connection: int = 1) -> int:
    """Client connections allowed at once: `wanted`, but never so many that the
    process runs out of descriptors (a quarter of the soft limit, at least
    `reserve`, stays free; a proxied connection costs `per_connection`)."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY:
        return wanted
    keep = max(reserve, soft // 4)
    return max(1, min(wanted, (soft - keep) // per_connection))


@dataclass
class Conn:
    """One client connection as the table sees it."""

    address: str
    opened: float
    done: bool = False
    """Its request headers were complete (a slow-header flood never gets here)."""
    close: Callable[[], None] = lambda: None


@dataclass
class ConnectionTable:
    """Connections held now, by address, under a per-address and a total cap."""

    per_address: int
    total: int
    conns: list[Conn] = field(default_factory=list)
    refused: int = 0
    evicted: int = 0

    def count(self, address: str) -> int:
        return sum(1 for c in self.conns if c.address == address)

    def admit(self, conn: Conn) -> tuple[bool, Conn | None]:
        """(admitted, the connection to cut for it). Over a cap, the oldest
        connection still reading its headers (of the same address when the
        address is over its own cap) makes room; none: refused."""
        victim: Conn | None = None
        if self.count(conn.address) >= self.per_address:
            victim = self._oldest_pending(conn.address)
            if victim is None:
                self.refused += 1
                return False, None
        elif len(self.conns) >= self.total:
            victim = self._oldest_pending(None)
            if victim is None:
                self.refused += 1
                return False, None
        if victim is not None:
            self.conns.remove(victim)
            self.evicted += 1
        self.conns.append(conn)
        return True, victim

    def _oldest_pending(self, address: str | None) -> Conn | None:
        pending = [c for c in self.conns if not c.done
                   and (address is None or c.address == address)]
        return min(pending, key=lambda c: c.opened, default=None)

    def release(self, conn: Conn) -> None:
        if conn in self.conns:
            self.conns.remove(conn)


@dataclass(frozen=True)
class Slot:
    """A connected page as the slot rule sees it."""

    priority: int
    joined: float
    heard: float | None = None
    """When it last sent something (None: never); a reading-only client never does."""


def pick_eviction(slots: Sequence[Slot], priority: int, now: float,
                  idle_s: float) -> int | None:
    """The index of the page that gives its slot to a newcomer of `priority`, or
    None (every page outranks it). Lower priorities go first, then pages not
    heard from for `idle_s` (or never: a client that only reads), then the
    longest quiet: a newcomer always gets a slot from its equals, and an
    operator from any anonymous page."""
    best: tuple[int, bool, float] | None = None
    index: int | None = None
    for i, s in enumerate(slots):
        if s.priority > priority:
            continue
        active = s.heard is not None and now - s.heard < idle_s
        key = (s.priority, active, s.joined if s.heard is None else s.heard)
        if best is None or key < best:
            best, index = key, i
    return index


class Occupant(Protocol):
    """A page holding a slot (`web.page_outbox.PageOutbox` is one)."""

    priority: int
    joined: float
    heard: float | None


PageT = TypeVar("PageT", bound=Occupant)


def evict_for(pages: Iterable[PageT], priority: int, idle_s: float,
              now: float | None = None) -> PageT | None:
    """The page of `pages` that gives its slot to a newcomer of `priority`
    (`pick_eviction`), or None."""
    listed = list(pages)
    index = pick_eviction([Slot(p.priority, p.joined, p.heard) for p in listed], priority,
                          time.monotonic() if now is None else now, idle_s)
    return None if index is None else listed[index]


# --- accept errors -------------------------------------------------------------------


class AcceptErrorLog:
    """The loop's exception handler: accept errors (descriptors exhausted) are
    counted and logged at most once per `period_s`, with a count; other
    errors too, by message, so no flood writes a traceback per event."""

    def __init__(self, logger: logging.Logger, period_s: float = 5.0) -> None:
        self.accept_errors = 0
        self.other_errors = 0
        self._log = RateLimitedLog(logger, period_s)

    def __call__(self, _loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        message = str(context.get("message", "error in the event loop"))
        exc = context.get("exception")
        if "accept" in message:
            self.accept_errors += 1
            self._log.warning("accept", "cannot accept connections: %s (%s)",
                              clip(exc, 120), message)
            return
        self.other_errors += 1
        self._log.warning(f"loop:{message[:60]}", "%s: %s", clip(message, 120),
                          clip(repr(exc), 200))

    def install(self, loop: asyncio.AbstractEventLoop) -> AcceptErrorLog:
        loop.set_exception_handler(self)
        return self


# --- the aiohttp side ------------------------------------------------------------------


@dataclass(frozen=True)
class Limits:
    """A surface's flood limits (from its settings)."""

    header_timeout_s: float = 10.0
    max_connections: int = 256
    max_connections_per_address: int = 64


class _Guarded(asyncio.Protocol):
    """Stands between the transport and aiohttp's handler: admits or cuts the
    connection, and cuts it when its first request's headers take too long."""

    def __init__(self, guard: Guard, inner: asyncio.Protocol) -> None:
        self.guard = guard
        self.inner = inner
        self.conn: Conn | None = None
        self.transport: asyncio.Transport | None = None
        self.timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        peer = transport.get_extra_info("peername")
        address = str(peer[0]) if isinstance(peer, tuple) and peer else "?"
        conn = Conn(address, time.monotonic(), close=transport.abort)
        admitted, victim = self.guard.table.admit(conn)
        if victim is not None:
            victim.close()
        if not admitted:
            self.guard.note_refused(address)
            transport.abort()
            return
        self.conn = conn
        self.transport = transport
        self.guard.pending[transport] = conn
        self.timer = asyncio.get_running_loop().call_later(
            self.guard.limits.header_timeout_s, self._slow, transport)
        self.inner.connection_made(transport)

    def _slow(self, transport: asyncio.Transport) -> None:
        if self.conn is not None and not self.conn.done:
            self.guard.slow += 1
            transport.abort()

    def data_received(self, data: bytes) -> None:
        if self.conn is not None:
            self.inner.data_received(data)

    def eof_received(self) -> bool | None:
        return self.inner.eof_received() if self.conn is not None else None

    def pause_writing(self) -> None:
        self.inner.pause_writing()

    def resume_writing(self) -> None:
        self.inner.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        if self.timer is not None:
            self.timer.cancel()
        if self.conn is None:
            return
        self.guard.table.release(self.conn)
        if self.transport is not None:
            self.guard.pending.pop(self.transport, None)
        self.inner.connection_lost(exc)


class Guard:
    """One surface's guard: its allow-list, its connection table, its counters."""

    def __init__(self, hosts: HostAllowList, limits: Limits, logger: logging.Logger,
                 per_connection: int = 1) -> None:
        self.hosts = hosts
        self.limits = limits
        self.table = ConnectionTable(limits.max_connections_per_address,
                                     descriptor_budget(limits.max_connections,
                                                       per_connection=per_connection))
        self.pending: dict[asyncio.BaseTransport, Conn] = {}
        self.hosts_refused = 0
        self.slow = 0
        self._warn = RateLimitedLog(logger)

    def warn(self, topic: str, text: str, *args: Any) -> None:
        """A refusal's log line, at most one per topic every few seconds."""
        self._warn.warning(topic, text, *args)

    def host_refused(self, host: str | None) -> None:
        self.hosts_refused += 1
        self._warn.warning("host", "refused a request for host %s (not a name this "
                           "service is served at; see allowed_hosts)", clip(host, 80))

    def note_refused(self, address: str) -> None:
        self._warn.warning("conn-cap", "refused a connection from %s: %d connections "
                           "held (at most %d, %d per address)", clip(address, 60),
                           len(self.table.conns), self.table.total, self.table.per_address)

    def hosts_of(self, transport: asyncio.BaseTransport | None) -> HostAllowList:
        """The allow-list for a connection: the names plus its local address."""
        sockname = transport.get_extra_info("sockname") if transport is not None else None
        local = str(sockname[0]) if isinstance(sockname, tuple) and sockname else None
        return self.hosts.reached_at(local)

    def headers_done(self, transport: asyncio.BaseTransport | None) -> None:
        conn = self.pending.pop(transport, None) if transport is not None else None
        if conn is not None:
            conn.done = True

    def counters(self) -> dict[str, int]:
        return {"connections": len(self.table.conns), "connections_refused":
                self.table.refused, "connections_evicted": self.table.evicted,
                "slow_headers_cut": self.slow, "hosts_refused": self.hosts_refused}

    def middleware(self) -> Callable[..., Awaitable[web.StreamResponse]]:
        """An aiohttp middleware: the headers are complete (the slow-header
        timer stops) and a foreign Host is answered 421."""

        @web.middleware
        async def check_host(request: web.Request,
                             handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
                             ) -> web.StreamResponse:
            self.headers_done(request.transport)
            host = request.headers.get("Host")
            if not self.hosts_of(request.transport).allows(host):
                self.host_refused(host)
                return web.Response(status=421, text=f"{clip(host, 80)} is not served here "
                                    "(see allowed_hosts)\n")
            return await handler(request)

        return check_host


def guard_for(s: WebSurface, bind_host: str, logger: logging.Logger,
              per_connection: int = 1) -> Guard:
    """A surface's guard from its settings: served at `bind_host` and the
    names of `allowed_hosts`, under its flood limits."""
    return Guard(HostAllowList.make(bind_host, s.allowed_hosts),
                 Limits(s.header_timeout_s, s.max_connections, s.max_connections_per_address),
                 logger, per_connection)


class GuardedSite(web.TCPSite):
    """A TCP site whose every connection passes the guard first."""

    __slots__ = ("guard",)

    def __init__(self, runner: web.BaseRunner, host: str | None, port: int,
                 guard: Guard, ssl_context: ssl.SSLContext | None = None) -> None:
        super().__init__(runner, host, port, ssl_context=ssl_context)
        self.guard = guard

    async def start(self) -> None:
        await web.BaseSite.start(self)
        loop = asyncio.get_running_loop()
        server = self._runner.server
        assert server is not None
        inner: Callable[[], asyncio.Protocol] = server
        self._server = await loop.create_server(
            lambda: _Guarded(self.guard, inner()), self._host, self._port,
            ssl=self._ssl_context, backlog=self._backlog)
        sockets = self._server.sockets
        self._bound_port = sockets[0].getsockname()[1] if sockets else self._port

    @property
    def listener(self) -> asyncio.Server | None:
        return self._server if isinstance(self._server, asyncio.Server) else None


@dataclass
class ListenerWatch:
    """Whether a service's listener still serves: a closed server, or a
    listening socket that is gone, makes `alive()` False for good (systemd,
    no longer getting watchdog pings, restarts the service)."""

    server: asyncio.Server | None
    dead: str = ""

    def alive(self) -> bool:
        if self.dead:
            return False
        server = self.server
        if server is None or not server.is_serving():
            self.dead = "the listener stopped serving"
        else:
            for sock in server.sockets:
                if sock.fileno() < 0:
                    self.dead = "the listening socket is gone"
        return not self.dead
