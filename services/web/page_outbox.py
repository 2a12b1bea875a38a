"""One connected web page's send side: its outbox, its sender, its stall cut.

The eye renderer and the dashboard give each page its own sender, so a
slow page never delays the others or the bus; a page that stops reading is
cut here and reconnects by itself (docs/architecture.md, "The web layer").
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Generic, Protocol, TypeVar

T = TypeVar("T")


class Socket(Protocol):
    """The part of a server WebSocket the sender reads (aiohttp's has it)."""

    @property
    def closed(self) -> bool: ...


class PageOutbox(Generic[T]):
    """A page's transport, the wake-up of its sender and the cut; `take` empties
    the service's store of what the page has not been sent (oldest first).
    Used only on the event loop."""

    def __init__(self, transport: asyncio.Transport | None,
                 take: Callable[[], list[T]], priority: int = 0) -> None:
        self.transport = transport
        self._take = take
        self._wake = asyncio.Event()
        self.cut_off = False
        self.priority = priority
        """Who the page is (0: anonymous); a full server evicts lower ones first
        (`guard.pick_eviction`)."""
        self.joined = time.monotonic()
        self.heard: float | None = None
        """When the page last sent something (`touch`); a reading-only client never does."""

    def touch(self) -> None:
        """The page sent something: it is in use, not a client that only reads."""
        self.heard = time.monotonic()

    def wake(self) -> None:
        """Something was put in the store: the sender sends it."""
        self._wake.set()

    def unsent(self) -> int:
        """Bytes written for this page that it has not taken yet (beyond the kernel's)."""
        return 0 if self.transport is None else self.transport.get_write_buffer_size()

    def cut(self) -> bool:
        """Drop the connection now, without a close handshake; True the first time."""
        first = not self.cut_off
        self.cut_off = True
        if self.transport is not None:
            self.transport.abort()
        return first

    async def send_until_closed(self, ws: Socket, send: Callable[[T], Awaitable[None]],
                                stall_s: Callable[[], float], log: logging.Logger,
                                max_unsent: int | None = None) -> float | None:
        """Send what is taken whenever the sender is woken, until `ws` closes.

        Returns the stall time (read before each send, so a live change
        applies at once) when the page stopped reading: a send did not drain
        within it, or more than `max_unsent` bytes wait for the page. The
        caller cuts the page then (and says so). None: the socket closed or
        broke (logged at debug level; the reader side cleans up).
        """
        stall = stall_s()
        try:
            while not ws.closed:
                await self._wake.wait()
                self._wake.clear()
                for item in self._take():
                    if max_unsent is not None and self.unsent() > max_unsent:
                        return stall
                    stall = stall_s()
                    async with asyncio.timeout(stall):
                        await send(item)
        except TimeoutError:
            return stall
        except (ConnectionError, RuntimeError) as exc:  # closing transport
            log.debug("page send failed: %r", exc)
        return None
