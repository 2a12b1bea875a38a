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
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiohttp
import psutil
import pytest

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.node import Node
from buddybot.core.testing import Process, buddybot_argv, free_port, retry_until, wait_port

pytestmark = pytest.mark.integration

NO_DISPLAY = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}


def http(port: int, path: str) -> tuple[int, str]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as resp:
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
    lids.put(m.EyeLidControl(stamp_ns=5, eye_id=m.EyeId.BOTH, top_lid_position=50,
                             bottom_lid_position=50))
    # Latched lids reach the renderer; a page connecting later gets them in its first batch.
    retry_until(lambda: json.loads(http(port, "/healthz")[1])["messages"] >= 1, 20,
                what="renderer got the latched lids")
    direction = probe.publisher(keys.EYES_DIRECTION)
    pupil = probe.publisher(keys.PUPIL)
    expression = probe.publisher(keys.EXPRESSION)

    def publish() -> None:
        expression.put(m.ScreenExpression(stamp_ns=6, action=m.ExpressionAction.ANIMATE_LOVE))
        pupil.put(m.PupilControl(stamp_ns=7, dilation_percentage=80))
        direction.put(m.EyesDirection(stamp_ns=8, yaw=12.5, pitch=-3))

    def complete(got: list[dict[str, Any]]) -> bool:
        return {"expression", "pupil", "direction"} <= {x["topic"] for x in got}

    got = asyncio.run(ws_collect(port, complete, publish))
    assert got[0]["topic"] == "hello" and got[0]["msg"]["max_yaw_deg"] == 40.0
    assert got[1] == {"topic": "lids", "msg": {"stamp_ns": 5, "eye_id": 2,
                                               "top_lid_position": 50.0,
                                               "bottom_lid_position": 50.0}}
    by_topic = {x["topic"]: x["msg"] for x in got}
    assert by_topic["expression"] == {"stamp_ns": 6, "action": 6}
    assert by_topic["pupil"]["dilation_percentage"] == 80.0
    assert by_topic["direction"] == {"stamp_ns": 8, "yaw": 12.5, "pitch": -3.0}


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
    got = asyncio.run(ws_collect(
        port, lambda g: any(x["topic"] == "direction" for x in g),
        lambda: direction.put(m.EyesDirection(stamp_ns=9, yaw=1, pitch=1))))
    assert [x["msg"]["stamp_ns"] for x in got if x["topic"] == "direction"] == [9]
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
