"""The dashboard server through a real router, with a plain WebSocket client (no browser).

Covers what a page cannot easily show: a busy port, a foreign origin, bad
requests from a page, camera images subscribed only while a page is there
and sent as JPEG at no more than `max_image_fps`.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import subprocess
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import aiohttp
import cv2
import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.dashboard import model
from buddybot.dashboard.settings import DashboardSettings
from buddybot.runtime.handles import Publisher
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    LOOPBACK,
    Collector,
    HeldSockets,
    Process,
    buddybot_argv,
    free_port,
    http_status,
    retry_until,
    wait_port,
)

pytestmark = pytest.mark.integration


def start_dashboard(spawn: Callable[..., Process], *args: str,
                    env: dict[str, str] | None = None,
                    nofile: int | None = None) -> tuple[Process, int]:
    port = free_port()
    proc = spawn("dashboard", "--port", str(port), *args, env=env, nofile=nofile)
    wait_port(port, 30)
    return proc, port


def health(port: int) -> dict[str, Any]:
    async def get() -> dict[str, Any]:
        async with aiohttp.ClientSession() as http, http.get(
                f"http://{LOOPBACK}:{port}/healthz") as resp:
            data: dict[str, Any] = await resp.json()
            return data

    return asyncio.run(get())


@contextlib.asynccontextmanager
async def camera_at_30_fps(publisher: Publisher[m.Image],
                           pixels: np.ndarray) -> AsyncIterator[None]:
    """Publish `pixels` as camera "side" at 30 fps while the block runs."""
    height, width = pixels.shape[:2]
    data = pixels.tobytes()

    async def publish() -> None:
        while True:
            publisher.put(m.Image(stamp_ns=m.now_ns(), frame_id="side", width=width,
                                  height=height, encoding="bgr8", data=data))
            await asyncio.sleep(1 / 30)

    task = asyncio.create_task(publish())
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def test_a_busy_port_is_one_line_and_exit_1(spawn: Callable[..., Process]) -> None:
    with socket.socket() as taken:
        taken.bind((LOOPBACK, 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = spawn("dashboard", "--port", str(port))
        assert proc.proc.wait(30) == 1
    lines = [x for x in proc.output().splitlines() if x.strip()]
    assert lines[-1].startswith(f"buddybot dashboard: cannot serve on 127.0.0.1:{port}: "
                                f"the port is taken by ")
    assert f"pid {os.getpid()}" in lines[-1]  # this test holds it
    assert "Traceback" not in proc.output()


def test_bad_requests_get_error_replies_and_foreign_origins_are_refused(
        spawn: Callable[..., Process]) -> None:
    proc, port = start_dashboard(spawn)
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    url = f"http://{LOOPBACK}:{port}/ws"

    async def talk() -> list[dict[str, Any]]:
        replies: list[dict[str, Any]] = []
        async with aiohttp.ClientSession() as http:
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect(url, origin="http://evil.example")
            assert refused.value.status == 403
            async with http.ws_connect(url, origin=f"http://{LOOPBACK}:{port}") as ws:
                for bad in ("not json", '{"op": "expression", "action": "EYE_WINK"}',
                            '{"op": "play"}'):
                    await ws.send_str(bad)
                    replies.append(await _next(ws, "reply"))
                await ws.send_bytes(b"\x00\x01")
                replies.append(await _next(ws, "reply"))
                # The socket still works after all that (the button needs control).
                await ws.send_str('{"op": "expression", "action": "EYE_SAD", "id": 7}')
                replies.append(await _next(ws, "reply"))
        return replies

    replies = asyncio.run(talk())
    assert [r["ok"] for r in replies] == [False, False, False, False, False]
    assert "bad request" in replies[0]["text"]
    assert "EYE_WINK" in replies[1]["text"]
    assert "sound" in replies[2]["text"]
    assert "binary" in replies[3]["text"]
    assert replies[4]["id"] == 7 and replies[4]["text"].startswith("take control first")
    assert proc.alive()
    assert health(port)["bad_requests"] == 4


def test_operator_requests_without_a_controller_or_with_a_stale_lease_say_why(
        spawn: Callable[..., Process]) -> None:
    """No eyes driver: taking control fails within the call timeout, naming it;
    a stale lease id is refused by the arbiter, and the page learns it all."""
    proc, port = start_dashboard(spawn)
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    url = f"http://{LOOPBACK}:{port}/ws"

    async def ask(ws: aiohttp.ClientWebSocketResponse, request: dict[str, Any]
                  ) -> tuple[dict[str, Any], float]:
        start = time.monotonic()
        await ws.send_str(json.dumps(request))
        reply = await _next(ws, "reply", timeout=20)
        assert reply["id"] == request["id"]
        return reply, time.monotonic() - start

    async def without() -> None:
        async with aiohttp.ClientSession() as http, http.ws_connect(
                url, origin=f"http://{LOOPBACK}:{port}") as ws:
            panel = await _next(ws, "leases")
            assert panel == {"known": False, "holding": False, "own": None, "leases": [],
                             "ended": []}
            reply, took = await ask(ws, {"op": "control", "on": True, "id": 1})
            assert not reply["ok"] and "eyes driver does not answer" in reply["text"]
            assert took < 10
            reply, _ = await ask(ws, {"op": "break", "lease_id": "L-old", "id": 2})
            assert not reply["ok"] and "eyes driver does not answer" in reply["text"]
            reply, _ = await ask(ws, {"op": "gaze", "yaw": 0.5, "pitch": 0, "id": 3})
            assert not reply["ok"] and reply["text"].startswith("take control first")

    asyncio.run(without())
    spawn("eyes")  # the arbiter

    async def stale() -> None:
        async with aiohttp.ClientSession() as http, http.ws_connect(
                url, origin=f"http://{LOOPBACK}:{port}") as ws:
            end = time.monotonic() + 30  # until the eyes driver's services are declared
            while True:
                reply, _ = await ask(ws, {"op": "break", "lease_id": "L-old", "id": 4})
                if "does not answer" not in reply["text"] or time.monotonic() > end:
                    break
            assert not reply["ok"] and "L-old" in reply["text"], reply
            reply, _ = await ask(ws, {"op": "control", "on": True, "id": 5})
            assert reply["ok"], reply
            end = time.monotonic() + 30  # the eyes driver declares its services one by one
            while True:
                reply, _ = await ask(ws, {"op": "expression", "action": "EYE_GRIN", "id": 6})
                if "does not answer" not in reply["text"] or time.monotonic() > end:
                    break
            assert reply["ok"], reply

    asyncio.run(stale())
    assert proc.alive()


@pytest.mark.integration
def test_the_operators_control_ends_when_no_page_is_left(
        spawn: Callable[..., Process], probe: Node, tmp_path: Path) -> None:
    """The operator lease used to hold until the switch was turned off, broken or the
    dashboard stopped: a laptop closed with control on kept the eyes for good. With
    no page open for `lease_idle_s` it is given back (a reload keeps it)."""
    leases = Collector[m.Leases](probe, keys.LEASES)
    spawn("eyes")
    config = tmp_path / "dashboard.toml"
    config.write_text("[dashboard]\nlease_idle_s = 2.0\n")
    _proc, port = start_dashboard(spawn, "--config", str(config))
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    url = f"http://{LOOPBACK}:{port}/ws"

    async def take_control_and_leave() -> None:
        async with aiohttp.ClientSession() as http, http.ws_connect(
                url, origin=f"http://{LOOPBACK}:{port}") as ws:
            await _next(ws, "hello")
            end = time.monotonic() + 30  # the arbiter's services may still be declared
            while True:
                await ws.send_str(json.dumps({"op": "control", "on": True, "id": 1}))
                reply = await _next(ws, "reply", timeout=20)
                if reply["ok"] or time.monotonic() > end:
                    break
            assert reply["ok"], reply

    asyncio.run(take_control_and_leave())  # the page is closed with control on
    held = leases.wait_for(lambda s: any(x.holder == "dashboard" for x in s.leases), 30,
                           "the operator lease")
    assert held.leases
    ended = leases.wait_for(lambda s: any(e.holder == "dashboard" and "no dashboard page"
                                          in e.message for e in s.ended), 30,
                            "the operator lease given back with no page left")
    assert not any(x.holder == "dashboard" for x in ended.leases)


FLOOD_LIMIT = 256
"""The dashboard's descriptor limit in the flood tests (systemd's default is 1,024)."""
FLOOD = 300
"""Unfinished requests held against it: more than it has descriptors."""


def test_slow_headers_beyond_the_descriptor_limit_lock_nobody_out(
        spawn: Callable[..., Process]) -> None:
    proc, port = start_dashboard(spawn, nofile=FLOOD_LIMIT)
    flood = HeldSockets(port, FLOOD)
    try:
        t0 = time.monotonic()
        status = http_status(port, "/", timeout=20.0)
        served_s = time.monotonic() - t0
        held = flood.open_count()
        ws_status = http_status(port, "/ws", websocket=True, origin=f"http://{LOOPBACK}:{port}")
    finally:
        flood.close()
    print(f"slow headers: {FLOOD} sent under a {FLOOD_LIMIT} limit, {held} still held, "
          f"a new request answered in {served_s * 1000:.0f} ms")
    assert status == 200 and ws_status == 101
    assert held <= 64   # the per-address cap; the rest were cut to make room
    counters = health(port)
    # Cut to make room, or by the header timeout when opening the flood took longer.
    assert counters["connections_evicted"] + counters["slow_headers_cut"] >= FLOOD - 64, counters
    assert proc.alive()
    output = proc.output()
    assert output.count("Traceback") == 0, output[-3000:]
    assert len(output.splitlines()) < 40, output[-3000:]   # a line per burst, not per event


def test_only_the_names_it_is_served_at_and_their_pages(spawn: Callable[..., Process]) -> None:
    """DNS rebinding: a site whose name points at the robot sends its own name as
    Host and as Origin; both are refused whatever they match."""
    _proc, port = start_dashboard(spawn)
    own = f"http://{LOOPBACK}:{port}"
    assert http_status(port, "/") == 200
    assert http_status(port, "/", host="attacker.example") == 421
    assert http_status(port, "/healthz", host=f"evil.test:{port}") == 421
    assert http_status(port, "/ws", websocket=True, host=f"evil.test:{port}",
                       origin=f"http://evil.test:{port}") == 421
    assert http_status(port, "/ws", websocket=True, origin=f"http://evil.test:{port}") == 403
    assert http_status(port, "/ws", websocket=True, origin="null") == 403
    assert http_status(port, "/ws", websocket=True, host=f"localhost:{port}",
                       origin=f"http://localhost:{port}") == 101
    assert http_status(port, "/ws", websocket=True, origin=own) == 101
    counters = health(port)
    assert counters["hosts_refused"] == 3 and counters["forbidden"] == 2


def test_eight_reading_pages_do_not_lock_out_the_ninth(spawn: Callable[..., Process]) -> None:
    _proc, port = start_dashboard(spawn)
    url = f"http://{LOOPBACK}:{port}/ws"
    origin = f"http://{LOOPBACK}:{port}"
    max_pages = DashboardSettings().max_pages

    async def read_all(ws: aiohttp.ClientWebSocketResponse) -> None:
        async for _msg in ws:
            pass

    async def scenario() -> tuple[dict[str, Any], int]:
        async with aiohttp.ClientSession() as http:
            readers = [await http.ws_connect(url, origin=origin) for _ in range(max_pages)]
            tasks = [asyncio.create_task(read_all(ws)) for ws in readers]
            async with http.ws_connect(url, origin=origin) as ninth:
                hello = await _next(ninth, "hello")
                await asyncio.wait_for(asyncio.wait(tasks, return_when="FIRST_COMPLETED"), 20)
                closed = sum(ws.closed for ws in readers)
            for ws in readers:
                await ws.close()
            for task in tasks:
                task.cancel()
        return hello, closed

    hello, closed = asyncio.run(scenario())
    assert "expressions" in hello
    assert closed == 1   # the longest quiet reader gave its slot
    counters = health(port)
    assert counters["evicted"] == 1 and counters["refused"] == 0


async def _next(ws: aiohttp.ClientWebSocketResponse, slot: str,
                timeout: float = 15.0) -> dict[str, Any]:
    """The value of the next text message of `slot` (others skipped)."""
    async with asyncio.timeout(timeout):
        while True:
            msg = await ws.receive()
            if msg.type == aiohttp.WSMsgType.TEXT:
                data = msg.json()
                if data["t"] == slot:
                    value: dict[str, Any] = data["v"]
                    return value
            elif msg.type in (aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                raise ConnectionError(f"closed while waiting for {slot}")


def test_images_only_while_a_page_is_connected_as_jpeg_at_the_rate_limit(
        spawn: Callable[..., Process], probe: Node) -> None:
    proc, port = start_dashboard(spawn, "--max-image-fps", "5", "--camera", "side")
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    assert not health(port)["watching_images"]
    publisher = probe.publisher(keys.CAMERA_IMAGE, camera="side")
    pixels = np.zeros((120, 160, 3), np.uint8)
    pixels[:, :80] = (0, 0, 255)  # left half red (BGR)

    async def watch() -> tuple[list[tuple[dict[str, Any], bytes]], float]:
        frames: list[tuple[dict[str, Any], bytes]] = []
        async with aiohttp.ClientSession() as http, http.ws_connect(
                f"http://{LOOPBACK}:{port}/ws") as ws:
            await asyncio.to_thread(retry_until, lambda: health(port)["watching_images"], 15)
            arrivals: list[float] = []
            async with camera_at_30_fps(publisher, pixels), asyncio.timeout(30):
                while len(frames) < 13:
                    msg = await ws.receive()
                    if msg.type == aiohttp.WSMsgType.BINARY:
                        arrivals.append(time.monotonic())
                        frames.append(model.unpack_image(msg.data))
        # The first frames may come late (the subscription is new): time the rest.
        return frames, arrivals[-1] - arrivals[2]

    frames, took = asyncio.run(watch())
    fps = (len(frames) - 3) / took
    print(f"images at {fps:.1f} fps with a 5 fps limit and 30 fps published")
    assert fps < 6.0
    header, jpeg = frames[-1]
    assert (header["width"], header["height"], header["frame_id"]) == (160, 120, "side")
    decoded = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert decoded is not None and decoded.shape == (120, 160, 3)
    assert abs(int(decoded[60, 20, 2]) - 255) < 20 and int(decoded[60, 140, 2]) < 20
    retry_until(lambda: not health(port)["watching_images"], 15,
                what="camera unsubscribed once the page left")
    assert proc.alive()


def test_malformed_samples_are_skipped_and_the_pages_still_get_the_good_ones(
        spawn: Callable[..., Process], probe: Node) -> None:
    proc, port = start_dashboard(spawn)
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    bad = probe.raw_publisher(probe.key(keys.RADAR_FRAMES, device="9"),
                              keys.RADAR_FRAMES.encoding)
    radar = probe.publisher(keys.RADAR_FRAMES, device="9")
    frame = m.LD2410TargetDataFrameArray(stamp_ns=m.now_ns(), device_id=9, sensors=[
        m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.MOVING,
                                movement_distance=123, movement_energy=50,
                                stationary_distance=0, stationary_energy=0,
                                detection_distance=123)])

    async def watch() -> list[dict[str, Any]]:
        async with aiohttp.ClientSession() as http, http.ws_connect(
                f"http://{LOOPBACK}:{port}/ws") as ws:
            await _next(ws, "hello")
            async with asyncio.timeout(30):
                while True:  # a stream's sample may be dropped on a busy machine: again
                    for payload in (b"{", b'{"stamp_ns": -1}', b"\xff" * 100):
                        bad.put(payload)
                    radar.put(frame)
                    try:
                        async with asyncio.timeout(1.0):
                            while True:
                                msg = await ws.receive()
                                if msg.type == aiohttp.WSMsgType.TEXT and \
                                        msg.json()["t"] == "radar":
                                    frames: list[dict[str, Any]] = msg.json()["v"]
                                    return frames
                    except TimeoutError:
                        continue

    frames = asyncio.run(watch())
    assert [(f["sensor"], f["moving_cm"]) for f in frames] == [("9/0", 123)]
    diagnostics = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="dashboard")
    diagnostics.wait_for(lambda d: d.values.get("malformed", 0) >= 3, 15,
                         "the malformed samples counted")
    assert proc.alive()


def test_live_parameters_change_the_image_rate_and_restart_only_ones_are_refused(
        spawn: Callable[..., Process], probe: Node, endpoint: str) -> None:
    proc, port = start_dashboard(spawn, "--max-image-fps", "20", "--camera", "side")
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")

    def param(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint,
                                            "--timeout", "10"),
                              capture_output=True, text=True, timeout=60)

    retry_until(lambda: param("list", "dashboard").returncode == 0, 30, 0.2,
                "dashboard params")
    listed = {p["name"]: p for p in json.loads(param("list", "dashboard", "--json").stdout)}
    assert set(listed) == set(DashboardSettings.__struct_fields__)
    assert {n for n, p in listed.items() if p["live"]} == {
        "max_image_fps", "jpeg_quality", "max_pages", "lease_idle_s"}
    refused = param("set", "dashboard", "port", "9999")
    assert refused.returncode == 1 and "port" in refused.stderr and "restart" in refused.stderr
    out_of_range = param("set", "dashboard", "max_image_fps", "0")
    assert out_of_range.returncode == 1 and "max_image_fps" in out_of_range.stderr

    publisher = probe.publisher(keys.CAMERA_IMAGE, camera="side")
    pixels = np.zeros((60, 80, 3), np.uint8)

    async def rates() -> tuple[float, float]:
        async with aiohttp.ClientSession() as http, http.ws_connect(
                f"http://{LOOPBACK}:{port}/ws") as ws:
            await asyncio.to_thread(retry_until, lambda: health(port)["watching_images"], 15)

            async def rate(frames: int) -> float:
                arrivals: list[float] = []
                async with asyncio.timeout(30):
                    while len(arrivals) < frames:
                        msg = await ws.receive()
                        if msg.type == aiohttp.WSMsgType.BINARY:
                            arrivals.append(time.monotonic())
                return (frames - 1) / (arrivals[-1] - arrivals[0])

            async def drain_until_gap(gap_s: float) -> None:
                """Read the frames queued while `param set` ran (at the old rate)
                until one comes `gap_s` after the one before: the new rate holds."""
                last = time.monotonic()
                async with asyncio.timeout(30):
                    while True:
                        msg = await ws.receive()
                        if msg.type == aiohttp.WSMsgType.BINARY:
                            now = time.monotonic()
                            if now - last >= gap_s:
                                return
                            last = now

            async with camera_at_30_fps(publisher, pixels):
                await rate(3)  # the subscription is new: the first frames may lag
                fast = await rate(12)
                changed = await asyncio.to_thread(param, "set", "dashboard", "max_image_fps",
                                                  "2")
                assert changed.returncode == 0, changed.stderr
                await drain_until_gap(0.3)
                slow = await rate(4)
            return fast, slow

    fast, slow = asyncio.run(rates())
    print(f"images at {fast:.1f} fps with a 20 fps limit, {slow:.1f} fps after set to 2")
    assert fast > 8.0 and slow < 3.0
    assert param("get", "dashboard", "max_image_fps").stdout.strip().splitlines()[-1] == "2.0"
    assert proc.alive()
