"""The pages: what they are shown, their queues, and the aiohttp application.

Each page has its own `Outbox` (newest per slot, radar frames appended) and
its own sender task: a slow page never delays the others or the bus, a page
that stops reading is cut after `STALL_S`, and camera frames are skipped
for a page whose socket is still full (a lower frame rate, not a backlog).
Only the dashboard's own page may open the WebSocket (it has buttons);
beyond loopback only with a login (`login.py`), and only an operator's
page may press them.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.resources
import logging
import time
from collections.abc import Callable
from typing import Any

import msgspec
from aiohttp import WSMsgType, web

from buddybot.contract import messages as m
from buddybot.dashboard import identity, login, model, radar_map
from buddybot.dashboard.bus import Bus
from buddybot.dashboard.settings import DashboardSettings
from buddybot.runtime.limits import BoundedDict, clip
from buddybot.runtime.node import RateLimitedLog
from buddybot.web import auth as web_auth
from buddybot.web.guard import (
    ANONYMOUS,
    IDLE_S,
    Guard,
    evict_for,
    origin_allowed,
    request_port,
)
from buddybot.web.page_outbox import PageOutbox

log = logging.getLogger("buddybot.dashboard")
_warn = RateLimitedLog(log)

STATIC = {"dashboard.js": "application/javascript", "dashboard.css": "text/css"}
STALL_S = 5.0
"""A page whose sends do not drain for this long is cut (it reconnects by itself)."""
IMAGE_BACKLOG_BYTES = 256 * 1024
"""A camera frame is skipped for a page with more than this still unsent."""
MAX_PENDING_CALLS = 4
"""Button presses being carried out at once (each one a bus call)."""


def now_s() -> float:
    return time.time()

# --- the pages -------------------------------------------------------------------------


class Page(PageOutbox[tuple[str, Any]]):
    """One connected page: its outbox (newest per slot, radar frames appended)
    and its sender."""

    def __init__(self, transport: asyncio.Transport | None, priority: int = ANONYMOUS,
                 role: str = login.OPERATOR, cookie: str | None = None) -> None:
        self.outbox = model.Outbox()
        super().__init__(transport, self.outbox.take, priority)
        self.images_skipped = 0
        self.role = role
        """operator (buttons) or viewer (watch only); operator on loopback without login."""
        self.cookie = cookie
        """The session cookie it connected with (None without login): checked again
        when a secret changes."""

    def put(self, slot: str, value: Any) -> None:
        self.outbox.put(slot, value)
        self.wake()

    def put_frames(self, frames: list[dict[str, Any]]) -> None:
        self.outbox.put_frames(frames)
        self.wake()


class Board:
    """What the pages show now, and the pages; used only on the event loop."""

    def __init__(self, s: DashboardSettings, eye_port: int, sounds: list[str],
                 configured: radar_map.Configured | None = None,
                 keep: frozenset[str] = frozenset()) -> None:
        self.s = s
        self.eye_port = eye_port
        self.pages: set[Page] = set()
        self.state: dict[str, Any] = {"status": {"bus": False},
                                      "leases": model.leases_view(None, None)}
        self.radar = model.RadarHistory(s.history_s)
        self.radar_latest: BoundedDict[str, dict[str, Any]] = BoundedDict(model.MAX_SENSORS)
        self.nodes = model.NodeTable(keep=keep)  # the nodes the config runs stay listed
        self.latency = model.Latency()
        self.sounds = sounds
        self.map = radar_map.RadarMap()
        self.configured = configured or radar_map.Configured()
        self._live_zones: list[radar_map.Zone] | None = None
        self._live_camera: dict[str, float] | None = None
        self._frame_width: int | None = None
        self._map_dirty = False
        self._update_map_sources()
        self.on_pages_changed: Callable[[int], None] = lambda _n: None
        self.refused = 0
        self.evicted = 0
        self.forbidden = 0
        self.viewer_refused = 0
        self.bad_requests = 0
        self.images_sent = 0

    def apply(self, s: DashboardSettings) -> None:
        """A live settings change: `max_pages` holds from the next connection."""
        self.s = s

    def hello(self, page_host: str | None, role: str = login.OPERATOR) -> dict[str, Any]:
        return {
            "role": role,
            "camera": self.s.camera, "history_s": self.s.history_s,
            "max_image_fps": self.s.max_image_fps,
            "eye_url": model.eye_page_url(self.s.eye_url, self.eye_port, page_host),
            "enums": model.enum_names(),
            "expressions": [a.name for a in m.ExpressionAction],
            "now": now_s(),
        }

    def join(self, page: Page, page_host: str | None) -> None:
        page.put("hello", self.hello(page_host, page.role))
        page.put("history", {"span_s": self.s.history_s, "now": now_s(),
                             "sensors": self.radar.snapshot(now_s())})
        page.put("sounds", self.sounds)
        page.put("nodes", self.nodes.view())
        page.put_frames(self.radar_latest.values())
        for slot, value in self.state.items():
            page.put(slot, value)
        self.pages.add(page)
        self.on_pages_changed(len(self.pages))

    def make_room(self, priority: int) -> bool:
        """Whether a page of `priority` may join: a free slot, or one taken
        from a page it outranks or equals (the longest quiet first), cut now."""
        if len(self.pages) < self.s.max_pages:
            return True
        victim = evict_for(self.pages, priority, IDLE_S)
        if victim is None:
            return False
        self.leave(victim)
        victim.cut()
        self.evicted += 1
        _warn.warning("evict", "a page was cut to make room for a new one (%d pages, "
                      "dashboard.max_pages)", self.s.max_pages)
        return True

    def leave(self, page: Page) -> None:
        if page in self.pages:
            self.pages.discard(page)
            self.on_pages_changed(len(self.pages))

    def _send(self, slot: str, value: Any, keep: bool = True) -> None:
        if keep:
            self.state[slot] = value
        for page in self.pages:
            page.put(slot, value)

    def _update_map_sources(self) -> None:
        c = self.configured
        self.map.set_zones(*radar_map.choose_zones(self._live_zones, c.zones))
        self.map.set_fov(*radar_map.choose_fov(self._live_camera, c.camera,
                                               self._frame_width or c.width))

    def _map_input(self, slot: str, value: Any, now: float) -> bool:
        """Feed the map what it draws from; True when `slot` is the map's alone."""
        if slot.startswith("targets:"):
            self.map.add(value, now)
            self._map_dirty = True
            return True
        if slot == "truth":
            self.map.set_truth(value, now)
            self._map_dirty = True
            return True
        if slot == "people":
            self.map.people = value
            self._map_dirty = True
            present = identity.present_view(value)
            if present != self.state.get("present"):
                self._send("present", present)
            return True
        if slot == "zones":
            self._live_zones = value
        elif slot == "camera_params":
            self._live_camera = value
        elif slot == "faces" and value.width != self._frame_width:
            self._frame_width = value.width
        elif slot == "controller":
            self.map.controller = value
            self._map_dirty = True
            return False
        else:
            return False
        self._update_map_sources()
        self._map_dirty = True
        return slot != "faces"

    def refresh_map(self, now: float | None = None) -> None:
        """Send the map's scene when it changed (also as trails age, from the
        service's loop); nothing before an angle radar was heard."""
        self._map_dirty = False
        scene = self.map.scene(now_s() if now is None else now)
        if scene is not None and scene != self.state.get("map"):
            self._send("map", scene)

    def deliver(self, batch: list[tuple[str, Any]]) -> None:
        """A batch from the mailbox: update what is remembered, push it to the pages."""
        now = now_s()
        for slot, value in batch:
            if self._map_input(slot, value, now):
                continue
            if slot == "radar":
                views: list[dict[str, Any]] = []
                for t, frames in value:
                    self.radar.add(t, frames)
                    views.extend(model.radar_view(t, frames))
                for page in self.pages:
                    page.put_frames(views)
                for v in views:
                    self.radar_latest[v["sensor"]] = v
            elif slot == "live":
                if self.nodes.update(value, now):
                    self._send("nodes", self.nodes.view(), keep=False)
            elif slot.startswith("diag:"):
                if self.nodes.diagnostics(value, now):
                    self._send("nodes", self.nodes.view(), keep=False)
            elif slot == "direction":
                msg, latency_ms = value
                self.latency.add(latency_ms)
                self._send("direction", {"msg": msgspec.to_builtins(msg),
                                         "latency": self.latency.view()})
            elif slot == "image":
                for page in self.pages:
                    if page.unsent() > IMAGE_BACKLOG_BYTES:
                        page.images_skipped += 1
                    else:
                        page.put("image", value)
            elif slot == "leases":
                self._send("leases", model.leases_view(*value))
            elif slot == "sounds":
                if value != self.sounds:
                    self.sounds = value
                    self._send("sounds", value, keep=False)
            elif isinstance(value, msgspec.Struct):
                self._send(slot, msgspec.to_builtins(value))
            else:
                self._send(slot, value)
        if self._map_dirty:
            self.refresh_map(now)

    def set_bus(self, up: bool) -> None:
        if self.state["status"].get("bus") != up:
            self._send("status", {"bus": up})

    def reply(self, page: Page, ident: int, ok: bool, text: str) -> None:
        page.put("reply", {"id": ident, "ok": ok, "text": text})


async def _sender(ws: web.WebSocketResponse, page: Page, board: Board) -> None:
    """Flush the page's outbox whenever something is in it; cut it when it stalls."""
    encode = msgspec.json.encode

    async def send(item: tuple[str, Any]) -> None:
        slot, value = item
        if slot == "image":
            await ws.send_bytes(value)
            board.images_sent += 1
        else:
            await ws.send_str(encode({"t": slot, "v": value}).decode())

    stalled = await page.send_until_closed(ws, send, lambda: STALL_S, log)
    if stalled is not None:
        _warn.warning("stall", "page cut: it has not read for %.0f s", stalled)
        page.cut()


# --- the web application ---------------------------------------------------------------


def _read_static() -> dict[str, bytes]:
    folder = importlib.resources.files("buddybot.dashboard") / "web"
    return {name: (folder / name).read_bytes() for name in ("index.html", *STATIC)}


class App:
    """The aiohttp application and the glue between the pages and the bus."""

    def __init__(self, board: Board, guard: Guard, gate: login.Gate | None = None) -> None:
        self.board = board
        self.guard = guard
        self.gate = gate
        """None: served on loopback, no login (every page is the operator's)."""
        self.pages_by_socket: dict[web.WebSocketResponse, Page] = {}
        self.priority_of: Callable[[web.Request], int] = lambda _request: ANONYMOUS
        """The slot priority of a page's request (a login hands operators more)."""
        self.bus: Bus | None = None
        self.calls = asyncio.Semaphore(MAX_PENDING_CALLS)
        self.sockets: set[web.WebSocketResponse] = set()
        self.files = _read_static()

    def make(self) -> web.Application:
        app = web.Application(middlewares=[self.guard.middleware()])
        app.router.add_get("/", self.index)
        app.router.add_get("/static/{name}", self.static)
        app.router.add_get("/ws", self.websocket)
        app.router.add_get("/healthz", self.health)
        app.router.add_get("/favicon.ico", self.no_icon)
        if self.gate is not None:
            self.gate.add_routes(app)
        app.on_shutdown.append(self.close_sockets)
        return app

    def _role(self, request: web.Request) -> str | None:
        """The request's role: operator without a gate, else its session's (None: none)."""
        return login.OPERATOR if self.gate is None else self.gate.role(request)

    async def index(self, request: web.Request) -> web.StreamResponse:
        if self._role(request) is None:
            raise web.HTTPSeeOther("/login")
        return web.Response(body=self.files["index.html"], content_type="text/html",
                            headers={"Cache-Control": "no-cache"})

    async def static(self, request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        if self._role(request) is None:
            raise web.HTTPUnauthorized(text="log in first: /login\n")
        if name not in STATIC:
            raise web.HTTPNotFound()
        return web.Response(body=self.files[name], content_type=STATIC[name],
                            headers={"Cache-Control": "no-cache"})

    async def no_icon(self, _request: web.Request) -> web.StreamResponse:
        return web.Response(status=204)

    async def health(self, _request: web.Request) -> web.StreamResponse:
        b = self.board
        return web.json_response({
            "pages": len(b.pages), "bus": b.state["status"].get("bus", False),
            "images_sent": b.images_sent, "bad_requests": b.bad_requests,
            "refused": b.refused, "evicted": b.evicted, "forbidden": b.forbidden,
            "viewer_refused": b.viewer_refused,
            **self.guard.counters(),
            "watching_images": self.bus is not None and self.bus.image_sub is not None})

    async def websocket(self, request: web.Request) -> web.StreamResponse:
        b = self.board
        origin = request.headers.get("Origin")
        if not origin_allowed(origin, self.guard.hosts_of(request.transport),
                              port=request_port(request.host)):
            b.forbidden += 1
            _warn.warning("origin", "refused a WebSocket from origin %s (not a name the "
                          "dashboard is served at; see dashboard.allowed_hosts)",
                          clip(origin, 80))
            return web.Response(status=403, text="only the dashboard's own page may connect\n")
        role = self._role(request)
        if role is None:
            b.forbidden += 1
            return web.Response(status=401, text="log in first: /login\n")
        priority = self.priority_of(request) if self.gate is None else login.PRIORITY[role]
        if not b.make_room(priority):
            b.refused += 1
            return web.Response(status=503, text=f"too many pages ({b.s.max_pages} max)\n")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=64 * 1024, compress=False)
        await ws.prepare(request)
        transport = request.transport
        page = Page(transport if isinstance(transport, asyncio.Transport) else None, priority,
                    role, request.cookies.get(web_auth.COOKIE) if self.gate else None)
        b.join(page, request.host)
        self.sockets.add(ws)
        self.pages_by_socket[ws] = page
        sender = asyncio.create_task(_sender(ws, page, b))
        tasks: set[asyncio.Task[None]] = set()
        log.info("page connected (%d pages)", len(b.pages))
        try:
            async for msg in ws:
                page.touch()
                if msg.type == WSMsgType.TEXT:
                    task = asyncio.create_task(self.command(page, msg.data))
                    tasks.add(task)
                    task.add_done_callback(tasks.discard)
                elif msg.type == WSMsgType.BINARY:
                    b.bad_requests += 1
                    b.reply(page, 0, False, "bad request: send JSON text, not binary")
                elif msg.type == WSMsgType.ERROR:
                    break
        finally:
            b.leave(page)
            self.sockets.discard(ws)
            self.pages_by_socket.pop(ws, None)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender
            log.info("page left (%d pages)", len(b.pages))
        return ws

    async def command(self, page: Page, text: str) -> None:
        """One request from a page; every one gets a reply (ok or a one-line error)."""
        b = self.board
        try:
            cmd = model.parse_command(text)
        except model.BadCommand as exc:
            b.bad_requests += 1
            b.reply(page, 0, False, str(exc))
            return
        if page.role != login.OPERATOR:
            b.viewer_refused += 1
            b.reply(page, cmd.id, False, "refused: a viewer may watch; only an operator may "
                    "press buttons or take the operator lease")
            return
        bus = self.bus
        if bus is None:
            b.reply(page, cmd.id, False, "not connected to the robot yet")
            return
        if self.calls.locked():
            b.reply(page, cmd.id, False, f"busy: {MAX_PENDING_CALLS} requests already running")
            return
        async with self.calls:
            try:
                ok, text_out = await asyncio.to_thread(bus.run_command, cmd)
            except Exception as exc:  # the service never dies for a button
                log.warning("request %r failed: %r", cmd, exc)
                ok, text_out = False, f"failed: {clip(exc, 200)}"
        b.reply(page, cmd.id, ok, text_out)

    async def end_stale_sessions(self) -> int:
        """Close the pages whose session no longer holds (its secret was rotated or
        revoked, or it expired); how many. Called from the service's loop."""
        if self.gate is None:
            return 0
        stale = [ws for ws, page in self.pages_by_socket.items()
                 if self.gate.session(page.cookie) is None]
        for ws in stale:
            log.info("page cut: its session ended (secret rotated or revoked, or expired)")
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(2.0):
                    await ws.close(code=4401, message=b"session ended: log in again")
        return len(stale)

    async def close_sockets(self, _app: web.Application) -> None:
        for ws in list(self.sockets):
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(2.0):
                    await ws.close(message=b"server shutdown")
