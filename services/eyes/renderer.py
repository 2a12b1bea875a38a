"""`buddybot run eye-renderer`: the eyes as a web page (seed eye_display_lld).

The seed's Electron app becomes a small aiohttp server, so any screen, a
tablet or a phone can be an eye:

* Zenoh subscriptions to direction, pupil, lids and expression (latched
  ones with history, so a restarted renderer shows the current state);
* each sample is handed to the asyncio loop and pushed over a WebSocket
  to every page at `/eyes?eye=left|right|both` (`/ws` carries the data;
  each page gets a greeting with its looks and the whole current state,
  then updates, coalesced per slot so a slow page never builds a backlog);
* one kiosk Chromium window per eye window planned by `placement.py` from
  the displays `screeninfo` finds (or `--display` geometries); none with
  `--no-browser`.

No display and no explicit placement: a warning and the pages are only
served (what `buddybot up --sim` on a headless machine wants). No display
with an explicit placement, or a placement the displays cannot satisfy:
exit status 2 with the placement rule's message (seed 5.4.3).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.resources
import logging
import sys
import tempfile
import uuid
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.node import Node
from buddybot.core.service import ServiceContext
from buddybot.eyes import kiosk, placement, wire
from buddybot.eyes.settings import EyeRendererSettings

log = logging.getLogger("buddybot.eye-renderer")

PAGE_EYES = ("left", "right", "both")
STATIC = {"eyes.js": "application/javascript", "eyes.css": "text/css"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", help="address to serve on (default from config, 127.0.0.1; "
                        "0.0.0.0 lets a tablet or phone be an eye)")
    parser.add_argument("--port", type=int, help="HTTP port (default from config, 8080; "
                        "0 = any free port)")
    parser.add_argument("--no-browser", action="store_true",
                        help="only serve the pages, open no kiosk windows")
    parser.add_argument("--browser", metavar="PATH",
                        help="browser executable (default: chromium on PATH)")
    parser.add_argument("--browser-arg", action="append", default=[], metavar="ARG",
                        help="extra browser flag (repeatable), e.g. --browser-arg=--disable-gpu")
    parser.add_argument("--eyes", choices=["left", "right", "both"],
                        help="which eyes to show (default both)")
    parser.add_argument("--left-display", type=int, metavar="N",
                        help="display number (1 = leftmost) for the robot's left eye")
    parser.add_argument("--right-display", type=int, metavar="N",
                        help="display number (1 = leftmost) for the robot's right eye")
    parser.add_argument("--display", action="append", default=[], metavar="WxH+X+Y",
                        help="use these displays instead of detecting them (repeatable)")


# --- displays and placement ----------------------------------------------------------


def detect_displays() -> list[placement.Display]:
    """Displays from screeninfo; none (not an exception) when there is no screen."""
    try:
        from screeninfo import get_monitors

        monitors = get_monitors()
    except Exception as exc:  # ScreenInfoError: no X/Wayland/enumerator
        log.debug("screeninfo found no display: %s", exc)
        return []
    return [placement.Display(mon.x, mon.y, mon.width, mon.height, mon.name or "")
            for mon in monitors]


def placement_request(args: argparse.Namespace, s: EyeRendererSettings) -> placement.Request:
    """Command line wins over config; 0/empty in config means 'not configured'."""
    eyes: tuple[placement.EyeName, ...] = tuple(s.eyes)
    if args.eyes:
        eyes = placement.EYES if args.eyes == "both" else (args.eyes,)
    left = args.left_display if args.left_display is not None else (s.left_display or None)
    right = args.right_display if args.right_display is not None else (s.right_display or None)
    return placement.Request(eyes=eyes, left_display=left, right_display=right)


class StartupError(Exception):
    """The renderer cannot start as configured (printed, exit status 2)."""


def plan_windows(args: argparse.Namespace, s: EyeRendererSettings) -> list[placement.Window]:
    """The kiosk windows to open (empty when serving pages only)."""
    if args.no_browser or not s.browser:
        return []
    request = placement_request(args, s)
    try:
        displays = [placement.parse_geometry(g) for g in args.display]
    except ValueError as exc:
        raise StartupError(f"--display: {exc}") from None
    if not displays:
        displays = detect_displays()
    if not displays and not request.explicit:
        log.warning("no display found: serving the eye pages only (no kiosk windows); "
                    "configure an eye placement to make this an error, or pass --no-browser "
                    "to silence this")
        return []
    try:
        windows = placement.plan(displays, request)
    except placement.PlacementError as exc:
        raise StartupError(str(exc)) from None
    log.info("displays: %s", placement.describe(displays))
    return windows


# --- the WebSocket hub ---------------------------------------------------------------


class Client:
    """One connected page: its outbox (latest per slot) and a wake-up event."""

    def __init__(self, eye: str) -> None:
        self.eye = eye
        self.outbox = wire.LatestState()
        self.wake = asyncio.Event()

    def push(self, slot: str, text: str) -> None:
        self.outbox.put(slot, text)
        self.wake.set()


class Hub:
    """Current state plus the connected pages; used only on the event loop."""

    def __init__(self, hello: wire.Hello) -> None:
        self.state = wire.LatestState()
        self.clients: set[Client] = set()
        self.hello_text = wire.encode("hello", hello)
        self.messages = 0

    def publish(self, msg: m.Message) -> None:
        text = self.state.put_message(msg)
        slot = wire.slot(msg)
        self.messages += 1
        for client in self.clients:
            client.push(slot, text)

    def join(self, eye: str) -> Client:
        client = Client(eye)
        client.push("hello", self.hello_text)
        for slot, text in self.state.items():
            client.push(slot, text)
        self.clients.add(client)
        return client


async def _sender(ws: web.WebSocketResponse, client: Client) -> None:
    """Flush the page's outbox whenever something new is in it; a page that
    went away ends this task quietly (the reader side cleans up)."""
    try:
        while not ws.closed:
            await client.wake.wait()
            client.wake.clear()
            for text in client.outbox.take():
                await ws.send_str(text)
    except (ConnectionError, RuntimeError) as exc:  # closing transport
        log.debug("page send failed: %r", exc)


def _read_static() -> dict[str, bytes]:
    folder = importlib.resources.files("buddybot.eyes") / "web"
    return {name: (folder / name).read_bytes() for name in ("eyes.html", *STATIC)}


def make_app(hub: Hub) -> web.Application:
    """The web application: page, static files, WebSocket, health."""
    files = _read_static()
    sockets: set[web.WebSocketResponse] = set()

    async def index(_request: web.Request) -> web.StreamResponse:
        raise web.HTTPFound("/eyes?eye=both")

    async def page(request: web.Request) -> web.StreamResponse:
        eye = request.query.get("eye", "both")
        if eye not in PAGE_EYES:
            return web.Response(status=400, text=f"bad eye {eye!r}: use left, right or both\n")
        return web.Response(body=files["eyes.html"], content_type="text/html",
                            headers={"Cache-Control": "no-cache"})

    async def static(request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        if name not in STATIC:
            raise web.HTTPNotFound()
        return web.Response(body=files[name], content_type=STATIC[name],
                            headers={"Cache-Control": "no-cache"})

    async def health(_request: web.Request) -> web.StreamResponse:
        pages: dict[str, int] = {}
        for client in hub.clients:
            pages[client.eye] = pages.get(client.eye, 0) + 1
        return web.json_response({"clients": len(hub.clients), "pages": pages,
                                  "messages": hub.messages})

    async def websocket(request: web.Request) -> web.StreamResponse:
        eye = request.query.get("eye", "both")
        if eye not in PAGE_EYES:
            return web.Response(status=400, text=f"bad eye {eye!r}: use left, right or both\n")
        ws = web.WebSocketResponse(heartbeat=5.0)
        await ws.prepare(request)
        client = hub.join(eye)
        sockets.add(ws)
        sender = asyncio.create_task(_sender(ws, client))
        log.info("page connected (eye=%s, %d pages)", eye, len(hub.clients))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.ERROR:
                    break
                # Pages have nothing to say; anything they send is ignored.
        finally:
            hub.clients.discard(client)
            sockets.discard(ws)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender
            log.info("page left (eye=%s, %d pages)", eye, len(hub.clients))
        return ws

    async def close_sockets(_app: web.Application) -> None:
        for ws in list(sockets):
            await ws.close(code=1001, message=b"server shutdown")

    app = web.Application()
    app.router.add_get("/", index)
    app.router.add_get("/eyes", page)
    app.router.add_get("/static/{name}", static)
    app.router.add_get("/ws", websocket)
    app.router.add_get("/healthz", health)
    app.on_shutdown.append(close_sockets)
    return app


# --- the service ---------------------------------------------------------------------


def _subscribe(node: Node, hub: Hub, loop: asyncio.AbstractEventLoop) -> None:
    def forward(msg: Any, _key: str) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is closing
            loop.call_soon_threadsafe(hub.publish, msg)

    for topic in (keys.EYES_DIRECTION, keys.PUPIL, keys.LIDS, keys.EXPRESSION):
        node.subscribe(topic, forward, delivery="inline")


async def serve(ctx: ServiceContext, node: Node, host: str, port: int,
                windows: list[placement.Window], browser: str | None) -> None:
    s = ctx.config.eye_renderer
    hub = Hub(wire.Hello(iris_color=s.iris_color, max_yaw_deg=s.max_yaw_deg,
                         max_pitch_deg=s.max_pitch_deg, server_id=uuid.uuid4().hex[:8]))
    runner = web.AppRunner(make_app(hub), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise StartupError(f"cannot serve on {host}:{port}: {exc.strerror or exc}") from None
    actual = runner.addresses[0][1] if runner.addresses else port
    view_host = "127.0.0.1" if host in ("0.0.0.0", "", "::") else host
    base = f"http://{view_host}:{actual}"
    _subscribe(node, hub, asyncio.get_running_loop())
    print(f"eye renderer serving {base}/eyes?eye=both", flush=True)
    log.info("eyes: %s/eyes?eye=left|right|both", base)

    kiosks: list[kiosk.KioskWindow] = []
    profiles = tempfile.TemporaryDirectory(prefix="buddybot-eyes-")
    try:
        for win in windows:
            assert browser is not None
            argv = kiosk.command(browser, kiosk.page_url(base, win.eye), win,
                                 Path(profiles.name) / win.eye, ctx.args.browser_arg)
            window = kiosk.KioskWindow(argv, f"{win.eye} eye on display {win.display_number}")
            window.start()
            kiosks.append(window)
        diag = node.diagnostics
        while not ctx.stop.is_set():
            await asyncio.sleep(0.2)
            for window in kiosks:
                window.poll()
            diag.values["pages"] = len(hub.clients)
            diag.values["messages"] = hub.messages
            diag.values["windows"] = len(kiosks)
    finally:
        for window in kiosks:
            window.stop()
        await runner.cleanup()
        profiles.cleanup()


def run(ctx: ServiceContext) -> int:
    s = ctx.config.eye_renderer
    args = ctx.args
    host = args.host or s.host
    port = s.port if args.port is None else args.port
    if not 0 <= port <= 65535:
        print(f"buddybot eye-renderer: --port {port} is not a TCP port", file=sys.stderr)
        return 2
    try:
        windows = plan_windows(args, s)
        browser = None
        if windows:
            browser = kiosk.find_browser(args.browser or s.browser_path)
            if browser is None:
                raise StartupError(
                    "no Chromium found for the kiosk windows: install it (scripts/chromium.sh), "
                    "set eye_renderer.browser_path, or run with --no-browser")
    except StartupError as exc:
        print(f"buddybot eye-renderer: {exc}", file=sys.stderr)
        return 2
    node = ctx.node()
    try:
        asyncio.run(serve(ctx, node, host, port, windows, browser))
    except StartupError as exc:
        print(f"buddybot eye-renderer: {exc}", file=sys.stderr)
        return 2
    finally:
        node.close()
    return 0
