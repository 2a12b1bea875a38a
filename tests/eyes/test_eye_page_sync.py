"""One face, many screens: pages of one renderer blink and look together.

A real router and eye-renderer process, and real Chromium pages (separate
browser contexts, as separate kiosk windows are): the left-eye and
right-eye pages must draw the same blinks in the same frame (within 17 ms
on the server clock), the same saccades, and a page opened late must join
the motion under way. Timing is read from each page's own record of what it
drew (`window.eyes.blinkLog`, `saccadeLog`: the first animation frame that
drew each event, converted to the server clock with the page's own clock
estimate), never from what the server meant to send.
"""

from __future__ import annotations

import asyncio
import json
import statistics
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, free_port, wait_port

from ..conftest import QUIET

pytestmark = [pytest.mark.integration, pytest.mark.browser, QUIET]  # frame times

FRAME_MS = 17.0
"""One frame at 60 Hz: two screens blinking within it blink together."""
W, H = 320, 200


@pytest.fixture
def renderer(spawn: Callable[..., Process], tmp_path: Path) -> int:
    """An eye-renderer (pages only) that blinks every 0.8-1.2 s, so a test sees
    many blinks quickly; its port."""
    cfg = tmp_path / "eyes.toml"
    cfg.write_text("[eye_renderer]\nblink_interval_min_s = 0.8\nblink_interval_max_s = 1.2\n")
    port = free_port()
    spawn("eye-renderer", "--port", str(port), "--no-browser", "--config", str(cfg))
    wait_port(port, 30)
    return port


@pytest.fixture
def contexts(browser: Any) -> Iterator[Callable[[], Any]]:
    """New browser contexts (one per screen), all closed afterwards."""
    made: list[Any] = []

    def new() -> Any:
        made.append(browser.new_context(viewport={"width": W, "height": H}))
        return made[-1]

    yield new
    for ctx in made:
        ctx.close()


def open_eye(context: Any, port: int, eye: str) -> Any:
    page = context.new_page()
    page.goto(f"http://127.0.0.1:{port}/eyes?eye={eye}")
    page.wait_for_function("window.eyes && window.eyes.ready && window.eyes.cur.calm < 0.002 "
                           "&& window.eyes.clock.samples.length >= 8", timeout=30_000)
    return page


def blinks(page: Any) -> dict[float, dict[str, Any]]:
    """The blinks the page drew, by the server's start time of each."""
    return {b["event_ms"]: b for b in page.evaluate("window.eyes.blinkLog")}


def wait_blinks(page: Any, count: int, after_ms: float) -> None:
    page.wait_for_function(
        f"window.eyes.blinkLog.filter(b => b.event_ms > {after_ms}).length >= {count}",
        timeout=60_000)


def server_now(page: Any) -> float:
    return float(page.evaluate("window.eyes.serverTime()"))


class ServerClock:
    """The renderer's clock read as a page reads it: a ping on a WebSocket of our own,
    answered by a pong with the server's time (an asyncio loop on its own thread, as
    Playwright's own loop owns this one)."""

    def __init__(self, port: int) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.session, self.ws = self._call(self._open(port))

    def _call(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(30)

    async def _open(self, port: int) -> tuple[aiohttp.ClientSession, Any]:
        session = aiohttp.ClientSession()
        return session, await session.ws_connect(f"http://127.0.0.1:{port}/ws?eye=left")

    async def _ask(self, t0: float) -> float:
        await self.ws.send_str(json.dumps({"topic": "ping", "msg": {"t0": t0}}))
        while True:
            got = json.loads((await self.ws.receive(timeout=10)).data)
            if got["topic"] == "pong" and got["msg"]["t0"] == t0:
                return float(got["msg"]["server_ms"])

    def read(self) -> float:
        """The server's clock (ms since the epoch) when our ping reached it."""
        return float(self._call(self._ask(time.monotonic())))

    def close(self) -> None:
        self._call(self.ws.close())
        self._call(self.session.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


def test_clock_offset_estimate_is_within_a_few_ms(contexts: Callable[[], Any],
                                                  renderer: int) -> None:
    """The page's idea of the server clock, read between two reads of the server's
    clock itself: it falls within them, give or take a few ms."""
    page = open_eye(contexts(), renderer, "left")
    server = ServerClock(renderer)
    errors, windows = [], []
    try:
        for _ in range(20):
            before = server.read()
            estimate = server_now(page)
            after = server.read()
            windows.append(after - before)
            # The estimate was taken somewhere inside [before, after].
            errors.append(0.0 if before <= estimate <= after
                          else min(abs(estimate - before), abs(estimate - after)))
    finally:
        server.close()
    clock = page.evaluate("window.eyes.clock")
    print(f"\nclock: offset {clock['offset']:.2f} ms from a round trip of {clock['rtt']:.2f} ms "
          f"({len(clock['samples'])} samples); estimate outside the read window by "
          f"median {statistics.median(errors):.2f} ms, max {max(errors):.2f} ms (read window "
          f"median {statistics.median(windows):.2f} ms)")
    assert clock["synced"] and 0 <= clock["rtt"] < 20
    assert max(errors) < 4.0, errors


def test_left_and_right_pages_blink_and_look_together(
        contexts: Callable[[], Any], renderer: int, probe: Node) -> None:
    left = open_eye(contexts(), renderer, "left")
    right = open_eye(contexts(), renderer, "right")
    since = max(server_now(left), server_now(right))
    for page in (left, right):
        wait_blinks(page, 4, since)
    wait_blinks(left, 4, since)
    lb, rb = blinks(left), blinks(right)
    same = sorted(t for t in lb.keys() & rb.keys() if t > since)
    assert len(same) >= 3, (sorted(lb), sorted(rb))
    # Every blink decided after both pages were up was drawn by both ...
    assert {t for t in lb if t > since and t < same[-1]} <= set(same)
    diffs = [abs(lb[t]["server_ms"] - rb[t]["server_ms"]) for t in same]
    lateness = [b[t]["server_ms"] - t for b in (lb, rb) for t in same]
    ahead = [t - b[t]["recv_ms"] for b in (lb, rb) for t in same]
    print(f"\nblinks drawn by both pages: {len(same)}; left-right difference "
          f"median {statistics.median(diffs):.2f} ms, max {max(diffs):.2f} ms; first frame "
          f"after the decided start: median {statistics.median(lateness):.2f} ms, "
          f"max {max(lateness):.2f} ms; arrived before their start: min {min(ahead):.2f} ms, "
          f"median {statistics.median(ahead):.2f} ms")
    # ... in the same frame, and on time (the first frame at or after the start).
    # (A start that falls within the pages' clock disagreement, a fraction of
    # a ms, of a frame boundary is drawn one frame apart: 16.7 ms, still
    # within the frame the issue allows.)
    assert max(diffs) < FRAME_MS, diffs
    assert all(-2.0 <= late < FRAME_MS + 4.0 for late in lateness), lateness

    # Looking around: the same glances, started in the same frame, the same way.
    probe.publisher(keys.EXPRESSION).put(
        m.ScreenExpression(stamp_ns=1, action=m.ExpressionAction.EYE_LOOK_RANDOM))
    for page in (left, right):
        page.wait_for_function(
            "window.eyes.saccadeLog.filter(s => s.purpose === 'glance').length >= 3",
            timeout=60_000)
    ls = {s["event_ms"]: s for s in left.evaluate("window.eyes.saccadeLog")}
    rs = {s["event_ms"]: s for s in right.evaluate("window.eyes.saccadeLog")}
    glances = sorted(t for t in ls.keys() & rs.keys() if ls[t]["purpose"] == "glance")
    assert len(glances) >= 3
    sdiffs = [abs(ls[t]["server_ms"] - rs[t]["server_ms"]) for t in glances]
    for t in glances:
        assert (ls[t]["yaw"], ls[t]["pitch"]) == (rs[t]["yaw"], rs[t]["pitch"])
    slate = [x[t]["server_ms"] - t for x in (ls, rs) for t in glances]
    sahead = [t - x[t]["recv_ms"] for x in (ls, rs) for t in glances]
    print(f"glances drawn by both: {len(glances)}; difference median "
          f"{statistics.median(sdiffs):.2f} ms, max {max(sdiffs):.2f} ms; first frame after "
          f"the start: max {max(slate):.2f} ms; arrived before their start: min "
          f"{min(sahead):.2f} ms")
    assert max(sdiffs) < FRAME_MS, sdiffs
    # And what is on screen mid-hold: both pages' offsets point the same way.
    held = """() => { const g = window.eyes.saccadeLog.at(-1), now = window.eyes.serverTime();
      return g && g.purpose === 'glance' && Math.abs(g.yaw) > 5
        && now > g.event_ms + g.duration_ms + 50 && now < g.event_ms + g.duration_ms + 250; }"""
    left.wait_for_function(held, timeout=60_000)
    lo = left.evaluate("[window.eyes.offset.yaw, window.eyes.offset.pitch]")
    ro = right.evaluate("[window.eyes.offset.yaw, window.eyes.offset.pitch]")
    print(f"offsets mid-glance: left {lo}, right {ro}")
    assert lo[0] * ro[0] > 0 and abs(lo[0] - ro[0]) < 0.5 and abs(lo[1] - ro[1]) < 0.5


def test_a_page_opened_late_joins_the_motion_under_way(
        contexts: Callable[[], Any], renderer: int) -> None:
    left = open_eye(contexts(), renderer, "left")
    right = open_eye(contexts(), renderer, "right")
    wait_blinks(left, 2, 0)
    late = open_eye(contexts(), renderer, "both")
    joined = server_now(late)
    for page in (left, right, late):
        wait_blinks(page, 2, joined)
    lb, rb, nb = blinks(left), blinks(right), blinks(late)
    after = sorted(t for t in nb if t > joined)
    assert after and after[0] in lb and after[0] in rb, (after, sorted(lb), sorted(rb))
    diffs = [abs(nb[t]["server_ms"] - x[t]["server_ms"]) for t in after[:2] if t in lb
             and t in rb for x in (lb, rb)]
    print(f"\nlate page's next blinks vs the others: max difference {max(diffs):.2f} ms")
    assert max(diffs) < FRAME_MS, diffs
    # It started from the saccade under way (sent with the state when it
    # connected), not from a new one of its own: its first one is the others'.
    first = late.evaluate("window.eyes.saccadeLog[0]")
    others = {s["event_ms"] for s in left.evaluate("window.eyes.saccadeLog")}
    assert first is not None and first["event_ms"] in others
    assert first["event_ms"] < joined
