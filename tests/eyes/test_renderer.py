"""`buddybot run eye-renderer` as a real process: HTTP, WebSocket, placement, kiosk windows,
its settings on `params/eye-renderer` through `buddybot param` (restart-only fields refused
naming the field, live looks reaching a connected page at once), and its inbox (pure).

The page itself is exercised in a real browser in test_eye_page.py;
here a plain aiohttp WebSocket client checks what the server pushes.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
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
from buddybot.eyes import renderer
from buddybot.eyes.renderer import Inbox
from buddybot.eyes.settings import EyeRendererSettings
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    HeldSockets,
    Process,
    buddybot_argv,
    free_port,
    http_status,
    retry_until,
    stuck_websocket,
    wait_port,
)

NO_DISPLAY = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}


def http(port: int, path: str, timeout: float = 10.0) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=timeout) as resp:
            return resp.status, resp.read().decode()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def start_renderer(spawn: Callable[..., Process], *args: str,
                   nofile: int | None = None) -> tuple[Process, int]:
    port = free_port()
    proc = spawn("eye-renderer", "--port", str(port), *args, env=NO_DISPLAY, nofile=nofile)
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


def test_the_server_clock_is_not_moved_by_a_step_of_the_wall_clock(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """NTP setting the clock of a computer with no real-time clock (or a virtual
    machine correcting its own in steps) moves the wall clock by seconds to hours;
    blinks and saccades are scheduled on the server clock, which goes on evenly."""
    start = renderer.now_ms()
    stepped = time.time_ns() + 3600 * 10**9
    monkeypatch.setattr(renderer.time, "time_ns", lambda: stepped)
    later = renderer.now_ms()
    assert 0.0 <= later - start < 1000.0, later - start
    assert abs(start - time.time() * 1000) < 60_000   # still ms since the epoch


@pytest.mark.integration
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


@pytest.mark.integration
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


@pytest.mark.integration
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


@pytest.mark.integration
def test_no_display_without_placement_serves_pages_with_a_warning(
    spawn: Callable[..., Process]
) -> None:
    proc, port = start_renderer(spawn)   # browser wanted, but no display here
    assert http(port, "/eyes?eye=both")[0] == 200
    assert "no display found: serving the eye pages only" in proc.output()
    assert proc.alive()


@pytest.mark.integration
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


@pytest.mark.integration
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


@pytest.mark.integration
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


@pytest.mark.integration
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


@pytest.mark.integration
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
    # DNS rebinding: a site's own name pointed at the robot (Origin matches Host):
    # the name is not one the renderer is served at (421, before any Origin rule).
    rebound = f"evil.example:{port}"
    assert asyncio.run(attempt(f"http://{rebound}", rebound)) == 421
    assert http_status(port, "/eyes", host="attacker.example") == 421
    for origin in (None, f"http://127.0.0.1:{port}", "http://tablet.local:8080"):
        assert asyncio.run(attempt(origin)) == 101, origin
    assert health(port)["forbidden"] == 4 and health(port)["hosts_refused"] == 2
    assert "refused a WebSocket from origin http://evil.example" in proc.output()
    assert proc.alive()


@pytest.mark.integration
def test_a_page_over_max_pages_takes_the_quietest_slot(
    spawn: Callable[..., Process], tmp_path: Path
) -> None:
    """Pages that only read cannot lock the real eyes out: a new page takes the
    slot of the page that sent nothing for the longest (kiosk pages ping every
    2 s, so a reading-only client goes first)."""
    proc, port = start_renderer(spawn, "--no-browser", "--config",
                                config_file(tmp_path, "max_pages = 3"))

    async def scenario() -> int:
        async with aiohttp.ClientSession() as session:
            url = f"http://127.0.0.1:{port}/ws?eye=left"
            pages = [await session.ws_connect(url) for _ in range(3)]
            for ws in pages:
                assert json.loads((await ws.receive(timeout=10)).data)["topic"] == "hello"
            for ws in pages[1:]:   # the first only reads; the others ping
                await ws.send_str('{"topic": "ping", "msg": {"t0": 1}}')
                while json.loads((await ws.receive(timeout=10)).data)["topic"] != "pong":
                    pass
            extra = await session.ws_connect(url)
            assert json.loads((await extra.receive(timeout=10)).data)["topic"] == "hello"
            msg = await pages[0].receive(timeout=10)
            while msg.type == aiohttp.WSMsgType.TEXT:
                msg = await pages[0].receive(timeout=10)
            closed = [ws.closed for ws in pages]
            for ws in (*pages, extra):
                await ws.close()
            return closed.index(True)

    assert asyncio.run(scenario()) == 0
    assert health(port)["evicted"] == 1 and health(port)["refused"] == 0
    assert "to make room for a new one" in proc.output()
    assert proc.alive()


@pytest.mark.integration
def test_slow_headers_beyond_the_descriptor_limit_lock_nobody_out(
        spawn: Callable[..., Process]) -> None:
    proc, port = start_renderer(spawn, "--no-browser", nofile=256)
    flood = HeldSockets(port, 300)
    try:
        status = http_status(port, "/eyes?eye=both", timeout=20.0)
        ws_status = http_status(port, "/ws?eye=both", websocket=True)
        # Held connections still queued are accepted (and older ones evicted) after
        # those two requests were served; on a busy machine, well after.
        held = len(flood.socks)
        retry_until(lambda: health(port)["connections_evicted"] >= held - 64, 60, 0.5,
                    f"all but 64 of the {held} held connections evicted "
                    f"({flood.failed} could not connect)")
    finally:
        flood.close()
    assert status == 200 and ws_status == 101
    assert proc.alive() and "Traceback" not in proc.output()


@pytest.mark.integration
def test_a_page_that_stops_reading_is_dropped(
    spawn: Callable[..., Process], probe: Node
) -> None:
    """A page that never reads while gaze floods in is cut once its sends stop
    draining; the renderer and its other pages carry on."""
    proc, port = start_renderer(spawn, "--no-browser")
    sock = stuck_page(port)
    flood = Flood(probe, every_topic=True)
    try:
        retry_until(lambda: health(port)["dropped"] >= 1, 180, 0.2, "stuck page dropped")
    finally:
        flood.stop()
    assert cut_off(sock)
    sock.close()
    assert health(port)["clients"] == 0
    # The counter moves before the log line has crossed the pipe: wait for it. The
    # reason is either the stalled sends or, when the page's missing pongs end the
    # socket first (a busy machine), the data left unsent at its end.
    proc.wait_for_output("page dropped (eye=both): it ", 30)
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


@pytest.mark.integration
def test_a_page_that_never_answers_a_ping_is_dropped_with_nothing_left_to_send(
    spawn: Callable[..., Process]
) -> None:
    """With no traffic, all that was sent fits in the kernel's buffers: the
    heartbeat's missing pong is what shows the page stopped reading, and it
    is counted and said as a drop like any other."""
    proc, port = start_renderer(spawn, "--no-browser")
    sock = stuck_page(port)
    try:
        retry_until(lambda: health(port)["dropped"] == 1, 60, 0.2, "the silent page dropped")
        assert cut_off(sock)
    finally:
        sock.close()
    proc.wait_for_output("page dropped (eye=both): it stopped answering pings", 30)
    assert health(port)["clients"] == 0


@pytest.mark.integration
def test_flood_and_stuck_pages_leave_a_real_page_fresh(
    spawn: Callable[..., Process], probe: Node
) -> None:
    """The finding: many never-reading pages plus a gaze flood froze the real
    page (state 17 s late) and /healthz. Now stuck pages are cut (each new
    one takes the slot of the longest-held silent page), samples coalesced:
    the real page keeps getting the newest gaze,
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
                # A real eye page pings (clock sync): it is heard from, so the
                # stuck pages give their slots first.
                await ws.send_str('{"topic": "ping", "msg": {"t0": 1}}')
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
    assert info["clients"] <= 16 and info["evicted"] >= 60 - 15, info
    assert flood.count > 1000, flood.count
    assert proc.alive()


# --- settings on `params/eye-renderer`, through `buddybot param` ---------------------------


RESTART = {"host", "port", "allowed_hosts", "header_timeout_s", "max_connections",
           "max_connections_per_address", "browser", "browser_path", "eyes", "left_display",
           "right_display", "style_file"}
"""Where the pages are served and the kiosk windows: decided once at start."""


LIVE_HERE = {"iris_color", "max_yaw_deg", "max_pitch_deg", "max_pages", "page_stall_s",
             "allowed_origins"}
"""Live fields this file checks (the motion's knobs are live too, tested with it)."""


def bb(endpoint: str, *args: str, timeout: str = "10") -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv(*args, "--connect", endpoint, "--timeout", timeout),
                          capture_output=True, text=True, timeout=60)


def start(spawn: Callable[..., Process], endpoint: str) -> int:
    """An eye-renderer serving pages only, answering on `params/eye-renderer`."""
    _, port = start_renderer(spawn, "--no-browser")
    retry_until(lambda: bb(endpoint, "param", "list", "eye-renderer",
                           timeout="1").returncode == 0, 30, 0.2, "eye-renderer params")
    return port


@pytest.mark.integration
def test_list_shows_every_field_and_restart_only_ones_are_refused(
        spawn: Callable[..., Process], endpoint: str) -> None:
    port = start(spawn, endpoint)
    listed = bb(endpoint, "param", "list", "eye-renderer")
    assert listed.returncode == 0, listed.stderr
    assert listed.stdout.splitlines()[0] == "[eye_renderer] of eye-renderer"
    rows = {line.split()[0]: line for line in listed.stdout.splitlines()[1:]}
    assert set(rows) == set(EyeRendererSettings.__struct_fields__)
    assert rows["port"].split()[1] == str(port) and rows["port"].endswith("restart")
    assert rows["iris_color"].endswith("live")
    as_json = {p["name"]: p for p in json.loads(
        bb(endpoint, "param", "list", "eye-renderer", "--json").stdout)}
    assert {name for name, p in as_json.items() if not p["live"]} == RESTART
    assert {name for name, p in as_json.items() if p["live"]} >= LIVE_HERE
    assert as_json["browser"]["value"] is False  # what it runs with: --no-browser

    for field, value in (("port", str(free_port())), ("host", "0.0.0.0"),
                         ("browser", "true"), ("left_display", "2")):
        refused = bb(endpoint, "param", "set", "eye-renderer", field, value)
        assert refused.returncode == 1, refused.stderr
        assert f"eye_renderer.{field} needs a restart" in refused.stderr
        assert "Traceback" not in refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    assert bb(endpoint, "param", "get", "eye-renderer", "port").stdout.strip() == str(port)
    out_of_range = bb(endpoint, "param", "set", "eye-renderer", "max_yaw_deg", "120")
    assert out_of_range.returncode == 1 and "allowed > 0 and <= 90" in out_of_range.stderr


async def hello_after_change(port: int, change: Callable[[], None],
                             timeout: float = 60.0) -> list[dict[str, Any]]:
    """Connect a page, wait for its first hello, make `change`, and collect until a
    second hello arrives. The page reads while `change` runs, as a browser would:
    a page that stops reading (and so answering pings) is cut by the renderer."""
    got: list[dict[str, Any]] = []

    async def read_until_hello() -> None:
        while sum(x["topic"] == "hello" for x in got) < 1:
            got.append(json.loads((await ws.receive()).data))

    async with aiohttp.ClientSession() as session, session.ws_connect(
            f"http://127.0.0.1:{port}/ws?eye=both") as ws, asyncio.timeout(timeout):
        first = json.loads((await ws.receive()).data)
        assert first["topic"] == "hello" and first["msg"]["iris_color"] == "#2f7fd0"
        reader = asyncio.create_task(read_until_hello())
        await asyncio.get_running_loop().run_in_executor(None, change)
        await reader
    return [first, *got]


@pytest.mark.integration
def test_live_looks_reach_a_connected_page(spawn: Callable[..., Process], endpoint: str,
                                           probe: Node) -> None:
    port = start(spawn, endpoint)

    def change() -> None:
        result = bb(endpoint, "param", "set", "eye-renderer", "iris_color", '"#a05a2c"')
        assert result.returncode == 0, result.stderr
        assert "(applied)" in result.stdout

    got = asyncio.run(hello_after_change(port, change))
    hellos = [x["msg"] for x in got if x["topic"] == "hello"]
    assert hellos[-1]["iris_color"] == "#a05a2c"
    assert hellos[-1]["server_id"] == hellos[0]["server_id"]  # the same server, restyled
    reply = probe.call(keys.PARAMS, m.ParamRequest(op="get", name="iris_color"),
                       node="eye-renderer")
    assert isinstance(reply, m.ParamReply) and reply.params[0].value == "#a05a2c"


@pytest.mark.integration
def test_a_lower_page_limit_applies_to_the_next_page(spawn: Callable[..., Process],
                                                     endpoint: str) -> None:
    port = start(spawn, endpoint)
    assert bb(endpoint, "param", "set", "eye-renderer", "max_pages", "1").returncode == 0

    async def two_pages() -> tuple[str, bool]:
        async with aiohttp.ClientSession() as session, session.ws_connect(
                f"http://127.0.0.1:{port}/ws?eye=left") as first, asyncio.timeout(20):
            hello = json.loads((await first.receive()).data)["topic"]
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws?eye=right") as second:
                assert json.loads((await second.receive()).data)["topic"] == "hello"
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(2):
                        while (await first.receive()).type == aiohttp.WSMsgType.TEXT:
                            pass
                return hello, first.closed

    # The change goes through the renderer's event loop: retried until it took effect.
    def took_the_slot() -> bool:
        hello, first_cut = asyncio.run(two_pages())
        return hello == "hello" and first_cut

    retry_until(took_the_slot, 30, 0.2, "a second page taking the first one's slot")


def test_inbox_hands_the_loop_only_the_newest_per_slot() -> None:
    """A flood from another thread reaches the loop as a few small batches with
    the newest value of each slot, in arrival order; nothing queues per sample."""
    batches: list[list[m.Message]] = []

    async def scenario() -> Inbox:
        loop = asyncio.get_running_loop()
        done = asyncio.Event()
        inbox = Inbox(loop, lambda batch: (batches.append(batch), done.set()))

        def flood() -> None:
            for i in range(20_000):
                inbox.put(m.EyesDirection(stamp_ns=i, yaw=i % 90, pitch=0.0))
                if i % 1000 == 0:
                    inbox.put(m.PupilControl(stamp_ns=i, dilation_percentage=i % 100))
            inbox.put(m.EyesDirection(stamp_ns=99_999, yaw=1.0, pitch=2.0))

        await loop.run_in_executor(None, flood)
        while not batches or batches[-1][-1].stamp_ns != 99_999:
            done.clear()
            await asyncio.wait_for(done.wait(), 10)
        return inbox

    inbox = asyncio.run(scenario())
    assert inbox.received == 20_000 + 20 + 1
    assert sum(len(b) for b in batches) + inbox.coalesced == inbox.received
    assert all(len(b) <= 2 for b in batches)          # one per slot, never a backlog
    assert len(batches) < 2_000                      # not one wake-up per sample
    assert batches[-1][-1] == m.EyesDirection(stamp_ns=99_999, yaw=1.0, pitch=2.0)
