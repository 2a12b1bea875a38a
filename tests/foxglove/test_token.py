"""The Foxglove bridge's token beyond loopback: the head parsing (pure), and a real
bridge process refusing clients without it and ending them when it is rotated.

`--login always` on 127.0.0.1 stands for a bridge served beyond loopback.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
import websockets

from buddybot.foxglove.token import given_token
from buddybot.tools.testing import Process, buddybot_argv, free_port
from buddybot.web import auth as web_auth

from .ws_client import FoxgloveClient


@pytest.mark.parametrize(("head", "fields", "token"), [
    (b"GET /?token=abc HTTP/1.1\r\nHost: x\r\n\r\n", {}, "abc"),
    (b"GET /?a=1&token=t%2Bu HTTP/1.1\r\n\r\n", {}, "t+u"),
    (b"GET / HTTP/1.1\r\n\r\n", {"authorization": "Bearer xyz"}, "xyz"),
    (b"GET / HTTP/1.1\r\n\r\n", {"authorization": "Basic xyz"}, None),
    (b"GET / HTTP/1.1\r\n\r\n", {}, None),
    (b"garbage", {}, None),
    (b"GET /?token= HTTP/1.1\r\n\r\n", {}, None),
])
def test_the_token_comes_from_the_query_or_a_bearer_header(
        head: bytes, fields: dict[str, str], token: str | None) -> None:
    assert given_token(head, fields) == token


@pytest.mark.integration
def test_beyond_loopback_the_bridge_needs_its_token_and_rotation_ends_connections(
        spawn: Callable[..., Process], tmp_path: Path) -> None:
    env = {"BUDDYBOT_STATE_DIR": str(tmp_path)}
    port = free_port()
    proc = spawn("foxglove", "--port", str(port), "--login", "always", env=env)
    proc.wait_for_output("foxglove bridge serving", timeout=30)
    assert "made its token" in proc.output()
    path = web_auth.secret_path("foxglove", tmp_path)
    token = web_auth.read_secret(path)
    assert token is not None

    async def scenario() -> None:
        for bad in ("", "/?token=wrong", f"/?token={token}x"):
            with pytest.raises(websockets.InvalidStatus) as refused:
                await FoxgloveClient.connect(port, bad)
            assert refused.value.response.status_code == 401
        client = await FoxgloveClient.connect(port, f"/?token={token}")
        assert client.server_info["name"] == "buddybot"
        done = subprocess.run(buddybot_argv("secret", "rotate", "foxglove"),
                              capture_output=True, text=True, timeout=60,
                              env={**os.environ, **env}, check=False)
        assert done.returncode == 0, done.stderr
        async with asyncio.timeout(15):
            with pytest.raises(websockets.ConnectionClosed):
                while True:
                    await client.ws.recv()
        with pytest.raises(websockets.InvalidStatus):
            await FoxgloveClient.connect(port, f"/?token={token}")
        fresh = web_auth.read_secret(path)
        client = await FoxgloveClient.connect(port, f"/?token={fresh}")
        await client.close()

    asyncio.run(scenario())
    assert proc.alive()
