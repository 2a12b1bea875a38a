"""The door in front of the Foxglove SDK's WebSocket server: names, origins, floods.

The SDK's server (Rust, `foxglove.start_server`) offers no hook on the
handshake's headers and no connection limits, and when its accept loop
meets descriptor exhaustion its listener is gone without a word. So the
SDK listens on loopback at a port of its own choosing, and this gate
listens where the bridge is configured to serve. For each connection it:

* admits it under the shared caps (`web.guard.ConnectionTable`;
  a proxied connection costs three descriptors, counted), the oldest one
  still sending its headers making room for a new one;
* reads the request headers within `header_timeout_s` (16 KiB at most);
* refuses a Host that is not a name the bridge is served at (421) and a
  browser Origin that is not allowed (403): the Foxglove app's origins and
  pages from this machine's loopback by default (`allowed_origins`);
* beyond loopback, refuses a request without the bridge's token (401,
  `token.py`), and ends an open connection once its token is rotated away;
* else forwards the bytes both ways, headers included, untouched.

It runs its own asyncio loop in a thread (the bridge is thread-based).
`alive()` is False once the gate's listener stops serving or the SDK's
listening socket is gone: the service then reports ERROR and stops feeding
the systemd watchdog, which restarts it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import threading
import time
from collections.abc import Collection
from typing import Any

from buddybot.foxglove.token import RECHECK_S, TokenCheck, given_token
from buddybot.runtime.endpoints import serve_failure
from buddybot.runtime.errors import ServeError
from buddybot.runtime.limits import clip
from buddybot.web.guard import (
    AcceptErrorLog,
    Conn,
    Guard,
    ListenerWatch,
    origin_allowed,
)

log = logging.getLogger("buddybot.foxglove")

MAX_HEAD_BYTES = 16 * 1024
"""A WebSocket handshake is well under 1 KiB; anything longer is not one."""
UPSTREAM_CHECK_S = 2.0
"""How often the SDK's listening socket is looked for."""
PIPE_CHUNK = 64 * 1024


def head_fields(head: bytes) -> dict[str, str]:
    """The header fields of a request head (names lower-case; the first of a
    repeated one wins); nothing for garbage."""
    fields: dict[str, str] = {}
    for line in head.decode("latin-1").split("\r\n")[1:]:
        name, colon, value = line.partition(":")
        if colon and name.strip():
            fields.setdefault(name.strip().lower(), value.strip())
    return fields


def sdk_listening(port: int) -> bool | None:
    """Whether this process still has a listening socket on `port` (the SDK's);
    None when it cannot be told (no psutil, or no descriptor left to look)."""
    try:
        import psutil

        conns = psutil.Process().net_connections(kind="tcp")
    except Exception:
        return None
    return any(c.status == psutil.CONN_LISTEN and c.laddr and c.laddr.port == port
               for c in conns)


class Gate:
    """The gate's listener, its loop thread and what it counted."""

    def __init__(self, guard: Guard, origins: Collection[str], upstream_port: int,
                 token: TokenCheck | None = None) -> None:
        self.guard = guard
        self.token = token
        """None: served on loopback, no token asked."""
        self.tokens_refused = 0
        self.origins = tuple(origins)
        self.upstream_port = upstream_port
        self.origins_refused = 0
        self.accept_log = AcceptErrorLog(log)
        self.watch = ListenerWatch(None)
        self.port = 0
        self.upstream_gone = ""
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="foxglove-gate",
                                        daemon=True)
        self._server: asyncio.Server | None = None
        self._next_check = 0.0

    def start(self, host: str, port: int) -> int:
        """Listen on host:port (ServeError, one line, when it cannot); the bound port."""
        self.accept_log.install(self._loop)
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(self._listen(host, port), self._loop)
        try:
            self._server = future.result(timeout=10.0)
        except OSError as exc:
            self.stop()
            why = os.strerror(exc.errno) if exc.errno else str(exc.strerror or exc)
            raise ServeError(serve_failure(host or "0.0.0.0", port, why)) from None
        self.watch = ListenerWatch(self._server)
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    async def _listen(self, host: str, port: int) -> asyncio.Server:
        return await asyncio.start_server(self._client, host or None, port,
                                          limit=MAX_HEAD_BYTES)

    def stop(self) -> None:
        async def close() -> None:
            if self._server is not None:
                self._server.close()
                for conn in list(self.guard.table.conns):
                    conn.close()

        if self._thread.is_alive():
            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(close(), self._loop).result(timeout=5.0)
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(5.0)

    def alive(self) -> bool:
        """False for good once the gate or the SDK stopped listening."""
        if not self.watch.alive():
            return False
        now = time.monotonic()
        if now >= self._next_check:
            self._next_check = now + UPSTREAM_CHECK_S
            self.check_upstream()
        return not self.upstream_gone

    def check_upstream(self) -> None:
        """Look for the SDK's listening socket now (once gone, it stays gone)."""
        if not self.upstream_gone and sdk_listening(self.upstream_port) is False:
            self.upstream_gone = "the Foxglove server's listening socket is gone"
            log.error("%s: restart the bridge", self.upstream_gone)

    def why_dead(self) -> str:
        return self.watch.dead or self.upstream_gone

    def counters(self) -> dict[str, int]:
        return {**self.guard.counters(), "origins_refused": self.origins_refused,
                "tokens_refused": self.tokens_refused,
                "accept_errors": self.accept_log.accept_errors}

    # -- one client --

    async def _client(self, reader: asyncio.StreamReader,
                      writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        address = str(peer[0]) if isinstance(peer, tuple) and peer else "?"
        conn = Conn(address, time.monotonic(), close=writer.transport.abort)
        admitted, victim = self.guard.table.admit(conn)
        if victim is not None:
            victim.close()
        if not admitted:
            self.guard.note_refused(address)
            writer.transport.abort()
            return
        try:
            await self._serve(conn, reader, writer)
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.LimitOverrunError,
                ValueError):
            pass
        except TimeoutError:
            self.guard.slow += 1
        finally:
            self.guard.table.release(conn)
            writer.transport.abort()

    async def _serve(self, conn: Conn, reader: asyncio.StreamReader,
                     writer: asyncio.StreamWriter) -> None:
        async with asyncio.timeout(self.guard.limits.header_timeout_s):
            head = await reader.readuntil(b"\r\n\r\n")
        conn.done = True
        fields = head_fields(head)
        host = fields.get("host")
        if not self.guard.hosts_of(writer.transport).allows(host):
            self.guard.host_refused(host)
            await _answer(writer, 421, "Misdirected Request",
                          f"{clip(host, 80)} is not served here (see foxglove.allowed_hosts)")
            return
        origin = fields.get("origin")
        if not origin_allowed(origin, None, listed=self.origins, loopback_any_port=True):
            self.origins_refused += 1
            self.guard.warn("origin", "refused a Foxglove connection from origin %s "
                                     "(see foxglove.allowed_origins)", clip(origin, 80))
            await _answer(writer, 403, "Forbidden", f"origin {clip(origin, 80)} may not "
                          "connect (see foxglove.allowed_origins)")
            return
        token = given_token(head, fields) if self.token is not None else None
        if self.token is not None and not self.token.allows(token):
            self.tokens_refused += 1
            self.guard.warn("token", "refused a Foxglove connection from %s: %s token",
                            conn.address, "no" if token is None else "a wrong")
            await _answer(writer, 401, "Unauthorized", "a token is required: connect to "
                          "ws://HOST:PORT/?token=... (`buddybot secret show foxglove`)")
            return
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        try:
            up_writer.write(head)
            piping = asyncio.gather(_pipe(reader, up_writer), _pipe(up_reader, writer),
                                    return_exceptions=True)
            if self.token is None:
                await piping
            else:
                await self._while_token_holds(token, piping)
        finally:
            up_writer.transport.abort()

    async def _while_token_holds(self, token: str | None, piping: asyncio.Future[Any]
                                 ) -> None:
        """Wait for the connection to end; end it first if its token stops holding."""
        assert self.token is not None
        while not piping.done():
            await asyncio.wait([piping], timeout=RECHECK_S)
            if not piping.done() and not self.token.allows(token):
                log.info("a Foxglove connection ended: its token was rotated or revoked")
                piping.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await piping
                return


async def _answer(writer: asyncio.StreamWriter, status: int, reason: str, text: str) -> None:
    body = (text + "\n").encode()
    writer.write(f"HTTP/1.1 {status} {reason}\r\nContent-Type: text/plain\r\n"
                 f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode() + body)
    with contextlib.suppress(ConnectionError, TimeoutError):
        async with asyncio.timeout(2.0):
            await writer.drain()


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """Copy until either side ends; then end the other (the gather's partner)."""
    try:
        while data := await reader.read(PIPE_CHUNK):
            writer.write(data)
            await writer.drain()
    finally:
        writer.transport.abort()
