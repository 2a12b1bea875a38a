"""A web page's send side (web/page_outbox.py): order, the stall cut, a gone page."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Coroutine
from typing import Any, TypeVar

import pytest

from buddybot.web.page_outbox import PageOutbox

log = logging.getLogger("test.page_outbox")
R = TypeVar("R")


class Transport(asyncio.Transport):
    def __init__(self, buffered: int = 0) -> None:
        super().__init__()
        self.buffered = buffered
        self.aborts = 0

    def get_write_buffer_size(self) -> int:
        return self.buffered

    def abort(self) -> None:
        self.aborts += 1


class Socket:
    def __init__(self) -> None:
        self.closed = False


class Store:
    def __init__(self) -> None:
        self.items: list[str] = []

    def take(self) -> list[str]:
        out, self.items = self.items, []
        return out


def page(transport: Transport | None = None) -> tuple[PageOutbox[str], Store]:
    store = Store()
    return PageOutbox(transport, store.take), store


def run(coro: Coroutine[Any, Any, R]) -> R:
    return asyncio.run(asyncio.wait_for(coro, 10.0))


def test_items_go_out_in_order_until_the_socket_closes() -> None:
    async def main() -> tuple[list[str], float | None]:
        out, store = page()
        ws = Socket()
        sent: list[str] = []
        done = asyncio.Event()

        async def send(item: str) -> None:
            sent.append(item)
            if item == "c":
                ws.closed = True
                done.set()

        task = asyncio.create_task(out.send_until_closed(ws, send, lambda: 1.0, log))
        store.items += ["a", "b"]
        out.wake()
        store.items.append("c")
        out.wake()
        await done.wait()
        return sent, await task

    assert run(main()) == (["a", "b", "c"], None)


@pytest.mark.parametrize("stall_s", [0.05, 0.2])
def test_a_send_that_does_not_drain_in_the_stall_time_reports_it(stall_s: float) -> None:
    async def main() -> float | None:
        out, store = page()
        never = asyncio.Event()

        async def send(_item: str) -> None:
            await never.wait()

        store.items.append("a")
        out.wake()
        return await out.send_until_closed(Socket(), send, lambda: stall_s, log)

    assert run(main()) == stall_s


def test_too_many_unsent_bytes_report_a_stall_before_sending() -> None:
    async def main() -> tuple[float | None, list[str]]:
        out, store = page(Transport(buffered=1001))
        sent: list[str] = []

        async def send(item: str) -> None:
            sent.append(item)

        store.items.append("a")
        out.wake()
        return await out.send_until_closed(Socket(), send, lambda: 2.0, log,
                                           max_unsent=1000), sent

    assert run(main()) == (2.0, [])


def test_a_broken_connection_ends_quietly() -> None:
    async def main() -> float | None:
        out, store = page()

        async def send(_item: str) -> None:
            raise ConnectionResetError("gone")

        store.items.append("a")
        out.wake()
        return await out.send_until_closed(Socket(), send, lambda: 2.0, log)

    assert run(main()) is None


def test_cut_aborts_the_transport_and_says_whether_it_was_the_first() -> None:
    transport = Transport(buffered=7)
    out, _store = page(transport)
    assert out.unsent() == 7
    assert out.cut() is True and out.cut() is False
    assert transport.aborts == 2 and out.cut_off
    no_transport, _ = page(None)
    assert no_transport.unsent() == 0 and no_transport.cut() is True
