"""The dashboard's login beyond loopback, through the real process and real HTTP.

`--login always` on 127.0.0.1 stands for a dashboard served beyond loopback
(the tests stay on loopback); the secrets live in a test-made state folder.
"""

from __future__ import annotations

import asyncio
import os
import ssl
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from buddybot.tools.testing import LOOPBACK, Process, buddybot_argv, retry_until
from buddybot.web import auth as web_auth

from ..conftest import ARTIFACTS
from .test_service import _next, health, start_dashboard

pytestmark = pytest.mark.integration
SHOTS = ARTIFACTS / "dashboard"


def secret(folder: Path, role: str) -> str:
    value = web_auth.read_secret(web_auth.secret_path(role, folder))
    assert value is not None
    return value


async def log_in(http: aiohttp.ClientSession, base: str, given: str) -> aiohttp.ClientResponse:
    return await http.post(f"{base}/login", data={"secret": given}, allow_redirects=False)


def cookie_of(resp: aiohttp.ClientResponse) -> str:
    return resp.cookies[web_auth.COOKIE].value


async def press(http: aiohttp.ClientSession, base: str, cookie: str,
                origin: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """Connect with `cookie`, press a button: (hello, reply)."""
    async with http.ws_connect(f"{base.replace('http', 'ws', 1)}/ws", origin=origin,
                               headers={"Cookie": f"{web_auth.COOKIE}={cookie}"}) as ws:
        hello = await _next(ws, "hello")
        await ws.send_str('{"op": "expression", "action": "EYE_SAD", "id": 3}')
        return hello, await _next(ws, "reply")


def test_beyond_loopback_only_a_login_gets_in_and_only_an_operator_presses(
        spawn: Callable[..., Process], tmp_path: Path) -> None:
    env = {"BUDDYBOT_STATE_DIR": str(tmp_path)}
    proc, port = start_dashboard(spawn, "--login", "always", env=env)
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    assert "made the operator secret" in proc.output()
    base = f"http://{LOOPBACK}:{port}"

    async def scenario() -> None:
        async with aiohttp.ClientSession() as http:
            # No login: the page redirects, its files and the WebSocket say 401.
            async with http.get(f"{base}/", allow_redirects=False) as resp:
                assert resp.status == 303 and resp.headers["Location"] == "/login"
            async with http.get(f"{base}/static/dashboard.js") as resp:
                assert resp.status == 401
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect(f"ws://{LOOPBACK}:{port}/ws", origin=base)
            assert refused.value.status == 401
            async with http.get(f"{base}/login") as resp:
                assert resp.status == 200 and 'name="secret"' in await resp.text()
            # A wrong secret, a forged cookie: refused.
            async with await log_in(http, base, "not-the-secret") as resp:
                assert resp.status == 401 and web_auth.COOKIE not in resp.cookies
            for body, kind in ((b"\xff\x00--x\r\ngarbage", "multipart/form-data; boundary=x"),
                               (b"secret=" + b"A" * 5000, "application/x-www-form-urlencoded"),
                               (b'{"secret": 1}', "application/json")):
                async with http.post(f"{base}/login", data=body, allow_redirects=False,
                                     headers={"Content-Type": kind}) as resp:
                    assert resp.status in (400, 401, 413), (kind, resp.status)
                    assert web_auth.COOKIE not in resp.cookies
            async with http.post(f"{base}/login", data={"secret": "x"}, allow_redirects=False,
                                 headers={"Origin": "http://evil.example"}) as resp:
                assert resp.status == 403
            forged = "operator.9999999999.x.AAAA"
            async with http.get(f"{base}/", allow_redirects=False,
                                headers={"Cookie": f"{web_auth.COOKIE}={forged}"}) as resp:
                assert resp.status == 303
            # The viewer watches; its button press is refused by the server.
            async with await log_in(http, base, secret(tmp_path, "viewer")) as resp:
                assert resp.status == 303
                set_cookie = resp.headers["Set-Cookie"]
                assert "HttpOnly" in set_cookie and "SameSite=Strict" in set_cookie
                assert "Secure" not in set_cookie  # plain HTTP
                viewer = cookie_of(resp)
            hello, reply = await press(http, base, viewer, base)
            assert hello["role"] == "viewer"
            assert reply["id"] == 3 and not reply["ok"] and "viewer" in reply["text"]
            # The operator's press reaches the bus (no controller here: it says why).
            async with await log_in(http, base, secret(tmp_path, "operator")) as resp:
                operator = cookie_of(resp)
            async with http.get(f"{base}/", allow_redirects=False,
                                headers={"Cookie": f"{web_auth.COOKIE}={operator}"}) as resp:
                assert resp.status == 200
            hello, reply = await press(http, base, operator, base)
            assert hello["role"] == "operator"
            assert reply["id"] == 3 and reply["text"].startswith("take control first")
            # Revoking the operator secret ends the open page and the cookie.
            ws = await http.ws_connect(f"ws://{LOOPBACK}:{port}/ws", origin=base,
                                       headers={"Cookie": f"{web_auth.COOKIE}={operator}"})
            await _next(ws, "hello")

            async def until_closed() -> None:
                """Read as a page does, also while the revoke runs: a page that stops
                reading (and answering pings) is cut for that instead (1006)."""
                while not ws.closed:
                    msg = await ws.receive()
                    if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                        break

            reader = asyncio.create_task(until_closed())
            done = await asyncio.get_running_loop().run_in_executor(None, lambda: subprocess.run(
                buddybot_argv("secret", "revoke"), capture_output=True, text=True, timeout=60,
                env={**os.environ, **env}, check=False))
            assert done.returncode == 0, done.stderr
            async with asyncio.timeout(60):
                await reader
            assert ws.close_code == 4401
            async with http.get(f"{base}/", allow_redirects=False,
                                headers={"Cookie": f"{web_auth.COOKIE}={operator}"}) as resp:
                assert resp.status == 303
            async with await log_in(http, base, secret(tmp_path, "viewer")) as resp:
                assert resp.status == 303  # the viewer's secret still holds

    asyncio.run(scenario())
    assert health(port)["viewer_refused"] == 1
    assert proc.alive()


def test_logout_ends_the_session_on_the_server_and_its_open_page(
        spawn: Callable[..., Process], tmp_path: Path) -> None:
    """The cookie used to hold for its 12 h after `POST /logout` (only the browser
    forgot it): a copy of it, or a page still open, kept the operator's powers."""
    env = {"BUDDYBOT_STATE_DIR": str(tmp_path)}
    proc, port = start_dashboard(spawn, "--login", "always", env=env)
    retry_until(lambda: health(port)["bus"], 30, what="dashboard on the bus")
    base = f"http://{LOOPBACK}:{port}"

    async def scenario() -> None:
        async with aiohttp.ClientSession() as http:
            async with await log_in(http, base, secret(tmp_path, "operator")) as resp:
                operator = cookie_of(resp)
            async with await log_in(http, base, secret(tmp_path, "operator")) as resp:
                other = cookie_of(resp)  # a second login: its own session
            with_cookie = {"Cookie": f"{web_auth.COOKIE}={operator}"}
            ws = await http.ws_connect(f"ws://{LOOPBACK}:{port}/ws", origin=base,
                                       headers=with_cookie)
            await _next(ws, "hello")

            async def until_closed() -> None:
                while not ws.closed:
                    msg = await ws.receive()
                    if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED):
                        break

            reader = asyncio.create_task(until_closed())
            async with http.post(f"{base}/logout", headers=with_cookie,
                                 allow_redirects=False) as resp:
                assert resp.status == 303 and resp.headers["Location"] == "/login"
            async with asyncio.timeout(60):
                await reader
            assert ws.close_code == 4401
            async with http.get(f"{base}/", allow_redirects=False, headers=with_cookie) as resp:
                assert resp.status == 303  # the copied cookie no longer holds
            hello, _reply = await press(http, base, other, base)
            assert hello["role"] == "operator"  # the other session is untouched

    asyncio.run(scenario())
    assert proc.alive() and "operator logged out" in proc.output()


def make_certificate(folder: Path) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 (the deployment's would be signed by its CA)."""
    cert, key = folder / "dash.pem", folder / "dash.key"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                    "ec_paramgen_curve:prime256v1", "-nodes", "-days", "1", "-subj",
                    f"/CN={LOOPBACK}", "-addext", f"subjectAltName=IP:{LOOPBACK}",
                    "-keyout", str(key), "-out", str(cert)],
                   check=True, capture_output=True, timeout=60)
    return cert, key


def test_tls_serves_https_with_the_given_certificate_and_secure_cookies(
        spawn: Callable[..., Process], tmp_path: Path) -> None:
    cert, key = make_certificate(tmp_path)
    env = {"BUDDYBOT_STATE_DIR": str(tmp_path / "state")}
    proc, port = start_dashboard(spawn, "--login", "always", "--tls-cert", str(cert),
                                 "--tls-key", str(key), env=env)
    base = f"https://{LOOPBACK}:{port}"
    trusted = ssl.create_default_context(cafile=str(cert))

    async def scenario() -> None:
        async with aiohttp.ClientSession() as http:
            async with http.get(f"{base}/login", ssl=trusted) as resp:
                assert resp.status == 200
            async with http.post(f"{base}/login", ssl=trusted, allow_redirects=False,
                                 data={"secret": secret(tmp_path / "state", "operator")}) as resp:
                assert resp.status == 303
                assert "Secure" in resp.headers["Set-Cookie"]
            with pytest.raises(aiohttp.ClientConnectorCertificateError):
                await http.get(f"{base}/login", ssl=ssl.create_default_context())
            with pytest.raises(aiohttp.ClientError):  # plain HTTP on the TLS port
                await http.get(f"http://{LOOPBACK}:{port}/login")

    asyncio.run(scenario())
    assert f"serving {base}/ (login required)" in proc.output()
    assert proc.alive()


def test_a_certificate_without_its_key_is_a_config_error(
        spawn: Callable[..., Process], tmp_path: Path) -> None:
    proc = spawn("dashboard", "--port", "0", "--tls-cert", str(tmp_path / "x.pem"))
    assert proc.proc.wait(30) == 2
    assert "tls_cert and tls_key go together" in proc.output()


@pytest.mark.browser
def test_a_viewer_logs_in_from_chromium_and_gets_a_page_without_buttons(
        browser: Any, spawn: Callable[..., Process], tmp_path: Path) -> None:
    """The login page in a real browser (its screenshot: docs/images/dashboard-login.png)."""
    env = {"BUDDYBOT_STATE_DIR": str(tmp_path)}
    _proc, port = start_dashboard(spawn, "--login", "always", env=env)
    page = browser.new_page(viewport={"width": 800, "height": 520})
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(f"http://{LOOPBACK}:{port}/")
    assert page.url.endswith("/login")
    page.fill("#secret", "wrong")
    page.click("button[type=submit]")
    page.wait_for_selector("text=Wrong secret")
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "dashboard-login.png"))
    page.fill("#secret", secret(tmp_path, "viewer"))
    page.click("button[type=submit]")
    page.wait_for_function("document.getElementById('conn').textContent === 'on the bus'",
                           timeout=30_000)
    assert page.evaluate("document.getElementById('control').disabled")
    assert page.evaluate("document.cookie") == ""  # HttpOnly: the page's scripts never see it
    assert errors == []
    page.close()
