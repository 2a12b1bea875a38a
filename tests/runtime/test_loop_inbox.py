"""LoopInbox: samples from other threads reach the loop in batches, one wake-up at a time."""

from __future__ import annotations

import asyncio
import itertools
import threading
from collections.abc import Callable

from buddybot.runtime.loop_inbox import LoopInbox


class ListInbox(LoopInbox[int]):
    """Keeps every sample (the simplest policy a subclass can choose)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, deliver: Callable[[list[int]], None],
                 min_interval_s: float) -> None:
        super().__init__(loop, deliver, min_interval_s)
        self.pending: list[int] = []
        self.wakeups = 0

    def put(self, value: int) -> None:
        with self._lock:
            self.received += 1
            self.pending.append(value)
            was = self._scheduled
            self._schedule()
            self.wakeups += not was

    def _take(self) -> list[int]:
        out, self.pending = self.pending, []
        return out


def test_a_burst_from_another_thread_arrives_whole_in_few_batches() -> None:
    async def main() -> tuple[list[list[int]], int, int]:
        loop = asyncio.get_running_loop()
        batches: list[list[int]] = []
        done = asyncio.Event()

        def deliver(batch: list[int]) -> None:
            batches.append(batch)
            if sum(map(len, batches)) == 1000:
                done.set()

        inbox = ListInbox(loop, deliver, min_interval_s=0.05)
        thread = threading.Thread(target=lambda: [inbox.put(i) for i in range(1000)])
        thread.start()
        thread.join()
        await asyncio.wait_for(done.wait(), 10)
        return batches, inbox.wakeups, inbox.received

    batches, wakeups, received = asyncio.run(main())
    assert [v for b in batches for v in b] == list(range(1000))  # nothing lost, in order
    assert received == 1000
    assert len(batches) == wakeups < 1000  # one wake-up per batch, not per sample


def test_batches_are_at_least_the_minimum_interval_apart() -> None:
    async def main() -> list[float]:
        loop = asyncio.get_running_loop()
        times: list[float] = []
        delivered = asyncio.Event()

        def deliver(_batch: list[int]) -> None:
            times.append(loop.time())
            delivered.set()

        inbox = ListInbox(loop, deliver, min_interval_s=0.2)
        for i in range(3):
            delivered.clear()
            inbox.put(i)
            await asyncio.wait_for(delivered.wait(), 10)
        return times

    times = asyncio.run(main())
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert len(times) == 3 and all(g >= 0.19 for g in gaps), gaps


def test_a_closed_loop_is_not_an_error() -> None:
    loop = asyncio.new_event_loop()
    loop.close()
    inbox = ListInbox(loop, lambda _b: None, min_interval_s=0.0)
    inbox.put(1)  # call_soon_threadsafe raises RuntimeError on a closed loop: swallowed
    assert inbox.pending == [1]
