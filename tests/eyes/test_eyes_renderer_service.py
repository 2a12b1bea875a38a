"""`buddybot run eye-renderer` as a real process: HTTP, WebSocket, placement, kiosk windows.

The page itself is exercised in a real browser in test_eyes_browser.py;
here a plain aiohttp WebSocket client checks what the server pushes.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import signal
import socket
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiohttp
import psutil
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Process,
    buddybot_argv,
    free_port,
    retry_until,
    stuck_websocket,
    wait_port,
)

pytestmark = pytest.mark.integration

NO_DISPLAY = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}


def http(port: int, path: str, timeout: float = 10.0) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=timeout) as resp:
            return resp.status, resp.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def start_renderer(spawn: Callable[..., Process], *args: str) -> tuple[Process, int]:
    port = free_port()
    proc = spawn("eye-renderer", "--port", str(port), *args, env=NO_DISPLAY)
    wait_port(port, 30)
    return proc, port


async def ws_collect(port: int, until: Callable[[list[dict[str, Any]]], bool],
                     action: Callable[[], None] | None = None, eye: str = "both",
                     timeout: float = 20.0) -> list[dict[str, Any]]:
    """Connect a WebSocket client, optionally act, and collect messages until `until`."""
    got: list[dict[str, Any]] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(
            f"http://127.0.0.1:{port}/ws?eye={eye}") as ws:
        if action:
            await asyncio.get_running_loop().run_in_executor(None, action)
        async with asyncio.timeout(timeout):
            while not until(got):
                msg = await ws.receive()
                assert msg.type == aiohttp.WSMsgType.TEXT, msg
                got.append(json.loads(msg.data))
    return got


def test_pages_and_static_files_are_served(spawn: Callable[..., Process]) -> None:
    _proc, port = start_renderer(spawn, "--no-browser")
    status, body = http(port, "/eyes?eye=left")
    assert status == 200 and "<canvas" in body and "/static/eyes.js" in body
    assert http(port, "/")[0] == 200  # redirected to /eyes?eye=both
    status, body = http(port, "/static/eyes.js")
    assert status == 200 and "requestAnimationFrame" in body
    assert http(port, "/static/eyes.css")[0] == 200
    status, body = http(port, "/eyes?eye=middle")
    assert status == 400 and "bad eye" in body
    assert http(port, "/static/../renderer.py")[0] == 404
    assert http(port, "/static/secret.txt")[0] == 404
    assert json.loads(http(port, "/healthz")[1])["clients"] == 0


def test_websocket_gets_hello_state_and_updates(
    spawn: Callable[..., Process], probe: Node
) -> None:
    _proc, port = start_renderer(spawn, "--no-browser")
    lids = probe.publisher(keys.LIDS)
    now = m.now_ns()   # real stamps: the runtime replaces implausible ones by the arrival time
    lids.put(m.EyeLidControl(stamp_ns=now + 5, eye_id=m.EyeId.BOTH, top_lid_position=50,
                             bottom_lid_position=50))
    # Latched lids reach the renderer; a page connecting later gets them in its first batch.
    retry_until(lambda: json.loads(http(port, "/healthz")[1])["messages"] >= 1, 20,
                what="renderer got the latched lids")
    direction = probe.publisher(keys.EYES_DIRECTION)
    pupil = probe.publisher(keys.PUPIL)
    expression = probe.publisher(keys.EXPRESSION)

    def publish() -> None:
        expression.put(m.ScreenExpression(stamp_ns=now + 6,
                                          action=m.ExpressionAction.ANIMATE_LOVE))
        pupil.put(m.PupilControl(stamp_ns=now + 7, dilation_percentage=80))
        direction.put(m.EyesDirection(stamp_ns=now + 8, yaw=12.5, pitch=-3,
                                      target_distance_cm=80.0))

    def complete(got: list[dict[str, Any]]) -> bool:
        return {"expression", "pupil", "direction"} <= {x["topic"] for x in got}

    got = asyncio.run(ws_collect(port, complete, publish))
    assert got[0]["topic"] == "hello" and got[0]["msg"]["max_yaw_deg"] == 40.0
    # The first batch: the renderer is on the bus, and the latched lids.
    assert {"topic": "status", "msg": {"bus": True}} in got[1:3]
    assert {"topic": "lids", "msg": {"stamp_ns": now + 5, "eye_id": 2, "top_lid_position": 50.0,
                                     "bottom_lid_position": 50.0}} in got[1:3]
    by_topic = {x["topic"]: x["msg"] for x in got}
    assert by_topic["expression"] == {"stamp_ns": now + 6, "action": 6}
    assert by_topic["pupil"]["dilation_percentage"] == 80.0
    assert by_topic["direction"] == {"stamp_ns": now + 8, "yaw": 12.5, "pitch": -3.0,
                                        "target_distance_cm": 80.0}


def test_malformed_samples_and_client_junk_are_survived(
    spawn: Callable[..., Process], probe: Node
) -> None:
    proc, port = start_renderer(spawn, "--no-browser")
    direction = probe.publisher(keys.EYES_DIRECTION)
    for bad in (b"", b"{}", b'{"stamp_ns": 1, "yaw": 500, "pitch": 0}', b"\xff" * 64):
        direction.put_bytes(bad)
    probe.publisher(keys.LIDS).put_bytes(b'{"stamp_ns": 1, "eye_id": 7, '
                                         b'"top_lid_position": 0, "bottom_lid_position": 0}')

    async def junk() -> None:
        async with aiohttp.ClientSession() as session, session.ws_connect(
                f"http://127.0.0.1:{port}/ws?eye=left") as ws:
            await ws.send_str("hello?")
            await ws.send_bytes(b"\x00\x01")
        async with aiohttp.ClientSession() as session:
            with pytest.raises(aiohttp.WSServerHandshakeError):
                await session.ws_connect(f"http://127.0.0.1:{port}/ws?eye=third")

    asyncio.run(junk())
    retry_until(lambda: "dropped malformed" in proc.output(), 20, what="malformed logged")
    now = m.now_ns()
    got = asyncio.run(ws_collect(
        port, lambda g: any(x["topic"] == "direction" for x in g),
        lambda: direction.put(m.EyesDirection(stamp_ns=now, yaw=1, pitch=1))))
    assert [x["msg"]["stamp_ns"] for x in got if x["topic"] == "direction"] == [now]
    assert proc.alive()


def test_no_display_without_placement_serves_pages_with_a_warning(
    spawn: Callable[..., Process]
) -> None:
    proc, port = start_renderer(spawn)   # browser wanted, but no display here
    assert http(port, "/eyes?eye=both")[0] == 200
    assert "no display found: serving the eye pages only" in proc.output()
    assert proc.alive()


@pytest.mark.parametrize(("args", "message"), [
    (["--eyes", "left"], "no display found"),
    (["--display", "800x480+0+0", "--eyes", "both"], "2 eyes configured (left, right) but only 1"),
    (["--display", "800x480+0+0", "--display", "800x480+800+0", "--right-display", "3"],
     "right eye configured on display 3 but only 2"),
    (["--display", "800x480"], "--display: bad display geometry"),
    (["--display", "800x480+0+0", "--browser", "/nonexistent/chromium"], "no Chromium found"),
])
def test_impossible_placement_exits_with_a_clear_error(
    tmp_path: Path, args: list[str], message: str
) -> None:
    proc = Process(buddybot_argv("run", "eye-renderer", "--connect", "tcp/127.0.0.1:9",
                                 "--port", str(free_port()), *args),
                   "renderer-bad", tmp_path, env=NO_DISPLAY)
    try:
        assert proc.proc.wait(30) == 2
        assert message in proc.output()
    finally:
        proc.stop()


def test_bad_renderer_config_is_refused(tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text('[eye_renderer]\niris_color = "blue"\n')
    proc = Process(buddybot_argv("run", "eye-renderer", "--config", str(cfg),
                                 "--connect", "tcp/127.0.0.1:9"), "renderer-cfg", tmp_path)
    try:
        assert proc.proc.wait(30) == 2
        assert "eye_renderer.iris_color" in proc.output()
    finally:
        proc.stop()


@pytest.mark.browser
def test_kiosk_windows_open_one_page_per_display(spawn: Callable[..., Process]) -> None:
    """Two (given) displays -> two browser processes, left and right page connected.

    No screen exists here, so the windows run headless; everything else
    (placement, argv, one profile per window, supervision) is the real path.
    """
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.skip("Debian chromium not installed (scripts/chromium.sh installs it)")
    proc, port = start_renderer(
        spawn, "--browser", chromium, "--display", "640x360+0+0", "--display", "640x360+640+0",
        "--browser-arg=--headless=new", "--browser-arg=--no-sandbox",
        "--browser-arg=--disable-gpu")

    def pages() -> dict[str, int]:
        return json.loads(http(port, "/healthz")[1])["pages"]

    assert retry_until(lambda: pages() == {"left": 1, "right": 1}, 60, 0.3,
                       "left and right kiosk pages connected")
    out = proc.output()
    assert "opening left eye on display 1 window" in out
    assert "opening right eye on display 2 window" in out
    browsers = [c for c in psutil.Process(proc.pid).children(recursive=True)
                if "chromium" in c.name()]
    assert browsers
    # A renderer killed outright (SIGKILL to it alone) still takes its windows with it.
    os.kill(proc.pid, signal.SIGKILL)
    retry_until(lambda: not any(b.is_running() and b.status() != psutil.STATUS_ZOMBIE
                                for b in browsers), 30, 0.2, "kiosk windows gone")


def test_a_window_that_exits_is_reopened(spawn: Callable[..., Process]) -> None:
    """A browser that dies at once (here `false`) is reopened with a backoff; the
    renderer itself stays up and keeps serving."""
    false = shutil.which("false")
    assert false is not None
    proc, port = start_renderer(spawn, "--browser", false, "--display", "640x360+0+0")
    retry_until(lambda: proc.output().count("opening both eye on display 1 window") >= 2, 30,
                0.2, "window reopened")
    assert "window exited (status 1); reopening in 1 s" in proc.output()
    assert http(port, "/eyes?eye=both")[0] == 200 and proc.alive()


# --- faults and attacks ------------------------------------------------------------------


def health(port: int) -> dict[str, Any]:
    return json.loads(http(port, "/healthz")[1])


def config_file(tmp_path: Path, text: str) -> str:
    path = tmp_path / "renderer.toml"
    path.write_text(f"[eye_renderer]\n{text}\n")
    return str(path)


def stuck_page(port: int, eye: str = "both") -> socket.socket:
    """A page that completes the handshake, then never reads again."""
    sock, head = stuck_websocket(port, f"/ws?eye={eye}")
    assert head.startswith(b"HTTP/1.1 101"), head
    return sock


def cut_off(sock: socket.socket) -> bool:
    """Whether the server has closed this connection (reads what is left first)."""
    try:
        while sock.recv(65536):
            pass
    except (ConnectionResetError, BrokenPipeError):
        pass
    return True


class Flood:
    """Publishes eyes/direction (and with `every_topic` pupil and per-eye lids
    too, so each batch to a page is bigger) as fast as it can from a thread,
    stamp = now, until stopped."""

    def __init__(self, probe: Node, every_topic: bool = False) -> None:
        self._every = every_topic
        self._pub = probe.publisher(keys.EYES_DIRECTION)
        self._pupil = probe.publisher(keys.PUPIL)
        self._lids = probe.publisher(keys.LIDS)
        self._stop = threading.Event()
        self.count = 0
        self.last: m.EyesDirection | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            now = m.now_ns()
            msg = m.EyesDirection(stamp_ns=now, yaw=(self.count % 60) - 30.0, pitch=0.0)
            self._pub.put(msg)
            self.last = msg
            self.count += 1
            if self._every:
                self._pupil.put(m.PupilControl(stamp_ns=now, dilation_percentage=self.count % 90))
                for eye in (m.EyeId.LEFT, m.EyeId.RIGHT):
                    self._lids.put(m.EyeLidControl(stamp_ns=now, eye_id=eye,
                                                   top_lid_position=self.count % 40,
                                                   bottom_lid_position=0))

    def stop(self) -> m.EyesDirection:
        self._stop.set()
        self._thread.join(10)
        assert self.last is not None
        return self.last


def test_foreign_origin_websocket_is_refused_with_403(
    spawn: Callable[..., Process], tmp_path: Path
) -> None:
    """A page on another site must not open the eye socket (cross-site WebSocket
    hijacking, DNS rebinding): 403 with a reason; the own origin, listed
    origins and programs without an Origin header connect."""
    cfg = config_file(tmp_path, 'allowed_origins = ["http://tablet.local:8080"]')
    proc, port = start_renderer(spawn, "--no-browser", "--config", cfg)
    url = f"http://127.0.0.1:{port}/ws?eye=both"

    async def attempt(origin: str | None, host: str | None = None) -> int:
        headers = {"Origin": origin} if origin else {}
        if host:
            headers["Host"] = host
        async with aiohttp.ClientSession() as session:
            try:
                async with session.ws_connect(url, headers=headers) as ws:
                    msg = await ws.receive(timeout=10)
                    assert json.loads(msg.data)["topic"] == "hello"
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    for origin in ("http://evil.example", f"http://127.0.0.1:{port + 1}", "null",
                   "http://evil.example:8080"):
        assert asyncio.run(attempt(origin)) == 403, origin
    # DNS rebinding: a site's own name pointed at the robot (Origin matches Host).
    rebound = f"evil.example:{port}"
    assert asyncio.run(attempt(f"http://{rebound}", rebound)) == 403
    for origin in (None, f"http://127.0.0.1:{port}", "http://tablet.local:8080"):
        assert asyncio.run(attempt(origin)) == 101, origin
    assert health(port)["forbidden"] == 5
    assert "refused a WebSocket from origin http://evil.example" in proc.output()
    assert proc.alive()


def test_pages_over_max_pages_are_refused_with_a_reason(
    spawn: Callable[..., Process], tmp_path: Path
) -> None:
    proc, port = start_renderer(spawn, "--no-browser", "--config",
                                config_file(tmp_path, "max_pages = 3"))

    async def scenario() -> None:
        async with aiohttp.ClientSession() as session:
            url = f"http://127.0.0.1:{port}/ws?eye=left"
            pages = [await session.ws_connect(url) for _ in range(3)]
            for ws in pages:
                assert json.loads((await ws.receive(timeout=10)).data)["topic"] == "hello"
            extra = await session.ws_connect(url)
            msg = await extra.receive(timeout=10)
            assert msg.type == aiohttp.WSMsgType.CLOSE, msg
            assert msg.data == aiohttp.WSCloseCode.TRY_AGAIN_LATER
            assert msg.extra == "too many pages (3 max)"
            await extra.close()
            # A page that leaves frees its place.
            await pages.pop().close()
            await asyncio.get_running_loop().run_in_executor(
                None, lambda: retry_until(lambda: health(port)["clients"] == 2, 20,
                                          what="page left"))
            again = await session.ws_connect(url)
            assert json.loads((await again.receive(timeout=10)).data)["topic"] == "hello"
            for ws in (*pages, again):
                await ws.close()

    asyncio.run(scenario())
    assert health(port)["refused"] == 1
    assert "refused a page: 3 pages connected" in proc.output()
    assert proc.alive()


def test_a_page_that_stops_reading_is_dropped(
    spawn: Callable[..., Process], probe: Node
) -> None:
    """A page that never reads while gaze floods in is cut once its sends stop
    draining; the renderer and its other pages carry on."""
    proc, port = start_renderer(spawn, "--no-browser")
    sock = stuck_page(port)
    flood = Flood(probe, every_topic=True)
    try:
        retry_until(lambda: health(port)["dropped"] >= 1, 60, 0.2, "stuck page dropped")
    finally:
        flood.stop()
    assert cut_off(sock)
    sock.close()
    assert health(port)["clients"] == 0
    assert "page dropped (eye=both): it has not read what was sent" in proc.output()
    # The next page is served as usual (a gaze put again until it shows: the
    # bus may still be draining the flood and drop a single one).
    seen = threading.Event()
    direction = probe.publisher(keys.EYES_DIRECTION)

    def keep_publishing() -> None:
        while not seen.wait(0.2):
            direction.put(m.EyesDirection(stamp_ns=m.now_ns(), yaw=33.0, pitch=0.0))

    def marked(got: list[dict[str, Any]]) -> bool:
        if any(x["topic"] == "direction" and x["msg"]["yaw"] == 33.0 for x in got):
            seen.set()
        return seen.is_set()

    publisher = threading.Thread(target=keep_publishing, daemon=True)
    publisher.start()
    try:
        got = asyncio.run(ws_collect(port, marked))
    finally:
        seen.set()
        publisher.join(10)
    assert got[0]["topic"] == "hello"
    assert proc.alive()


def test_flood_and_stuck_pages_leave_a_real_page_fresh(
    spawn: Callable[..., Process], probe: Node
) -> None:
    """The finding: many never-reading pages plus a gaze flood froze the real
    page (state 17 s late) and /healthz. Now extra pages are refused, stuck
    ones cut, samples coalesced: the real page keeps getting the newest gaze,
    /healthz answers, and the last gaze of the flood arrives."""
    proc, port = start_renderer(spawn, "--no-browser")
    seen: list[dict[str, Any]] = []
    ready = threading.Event()
    done = threading.Event()

    async def real_page() -> None:
        async with aiohttp.ClientSession() as session, session.ws_connect(
                f"http://127.0.0.1:{port}/ws?eye=both") as ws:
            ready.set()
            while not done.is_set():
                try:
                    msg = await ws.receive(timeout=0.5)
                except TimeoutError:
                    continue
                if msg.type != aiohttp.WSMsgType.TEXT:
                    break
                data = json.loads(msg.data)
                if data["topic"] == "direction":
                    seen.append(data["msg"])

    page = threading.Thread(target=lambda: asyncio.run(real_page()), daemon=True)
    page.start()
    assert ready.wait(20)
    stuck = [stuck_page(port) for _ in range(60)]
    flood = Flood(probe)
    try:
        end = time.monotonic() + 8
        while time.monotonic() < end:
            # /healthz never waits behind page traffic (it timed out before).
            assert http(port, "/healthz", timeout=10)[0] == 200
            # The page gets gaze published within the last few seconds (it got
            # 17 s old gaze before), generous for a busy shared machine.
            retry_until(lambda: seen and m.now_ns() - seen[-1]["stamp_ns"] < 3e9, 10, 0.05,
                        "fresh gaze on the real page")
    finally:
        flood.stop()
        info = health(port)
    direction = probe.publisher(keys.EYES_DIRECTION)
    try:
        retry_until(lambda: direction.put(m.EyesDirection(stamp_ns=m.now_ns(), yaw=33.0,
                                                          pitch=0.0))
                    or (seen and seen[-1]["yaw"] == 33.0), 10, 0.1, "gaze after the flood")
    finally:
        done.set()
        page.join(10)
        for sock in stuck:
            sock.close()
    assert info["clients"] <= 16 and info["refused"] >= 60 - 15, info
    assert flood.count > 1000, flood.count
    assert proc.alive()
