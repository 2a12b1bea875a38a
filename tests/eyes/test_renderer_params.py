"""The eye-renderer's settings on `params/eye-renderer`, through `buddybot param`
as a process: listed like every service's, restart-only fields
refused naming the field, live looks reaching a connected page at once."""

from __future__ import annotations

import asyncio
import json
import subprocess
from collections.abc import Callable
from typing import Any

import aiohttp
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.eyes.settings import EyeRendererSettings
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, buddybot_argv, free_port, retry_until, wait_port

pytestmark = pytest.mark.integration

NO_DISPLAY = {"DISPLAY": "", "WAYLAND_DISPLAY": ""}
RESTART = {"host", "port", "browser", "browser_path", "eyes", "left_display", "right_display",
           "style_file"}
"""Where the pages are served and the kiosk windows: decided once at start."""
LIVE_HERE = {"iris_color", "max_yaw_deg", "max_pitch_deg", "max_pages", "page_stall_s",
             "allowed_origins"}
"""Live fields this file checks (the motion's knobs are live too, tested with it)."""


def bb(endpoint: str, *args: str, timeout: str = "10") -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv(*args, "--connect", endpoint, "--timeout", timeout),
                          capture_output=True, text=True, timeout=60)


def start(spawn: Callable[..., Process], endpoint: str) -> int:
    """An eye-renderer serving pages only, answering on `params/eye-renderer`."""
    port = free_port()
    spawn("eye-renderer", "--no-browser", "--port", str(port), env=NO_DISPLAY)
    wait_port(port, 30)
    retry_until(lambda: bb(endpoint, "param", "list", "eye-renderer",
                           timeout="1").returncode == 0, 30, 0.2, "eye-renderer params")
    return port


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
                             timeout: float = 20.0) -> list[dict[str, Any]]:
    """Connect a page, wait for its first hello, make `change`, and collect until a
    second hello arrives."""
    got: list[dict[str, Any]] = []
    async with aiohttp.ClientSession() as session, session.ws_connect(
            f"http://127.0.0.1:{port}/ws?eye=both") as ws, asyncio.timeout(timeout):
        first = json.loads((await ws.receive()).data)
        assert first["topic"] == "hello" and first["msg"]["iris_color"] == "#2f7fd0"
        await asyncio.get_running_loop().run_in_executor(None, change)
        while sum(x["topic"] == "hello" for x in got) < 1:
            got.append(json.loads((await ws.receive()).data))
    return [first, *got]


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


def test_a_lower_page_limit_applies_to_the_next_page(spawn: Callable[..., Process],
                                                     endpoint: str) -> None:
    port = start(spawn, endpoint)
    assert bb(endpoint, "param", "set", "eye-renderer", "max_pages", "1").returncode == 0

    async def two_pages() -> tuple[str, int | None]:
        async with aiohttp.ClientSession() as session, session.ws_connect(
                f"http://127.0.0.1:{port}/ws?eye=left") as first, asyncio.timeout(20):
            hello = json.loads((await first.receive()).data)["topic"]
            async with session.ws_connect(f"http://127.0.0.1:{port}/ws?eye=right") as second:
                msg = await second.receive()
                assert msg.type == aiohttp.WSMsgType.CLOSE, msg
                return hello, second.close_code

    # The change goes through the renderer's event loop: retried until it took effect.
    def refused() -> bool:
        hello, code = asyncio.run(two_pages())
        return hello == "hello" and code == 1013

    retry_until(refused, 20, 0.2, "a second page refused with code 1013")
