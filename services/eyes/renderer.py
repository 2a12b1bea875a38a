"""`buddybot run eye-renderer`: the eyes as a web page.

A small aiohttp server rather than a desktop (Electron) app, so any
screen, a tablet or a phone can be an eye. Zenoh subscriptions to
direction, pupil, lids and expression feed a WebSocket to every page at
`/eyes?eye=left|right|both`, newest sample per slot so a flood or a slow
page never builds a backlog; the HTTP server starts before the Zenoh node
(a calm "connecting" face without a router); one kiosk Chromium window per
eye window planned by `placement.py`; one `motion.MotionScheduler` decides
every blink and saccade once for all pages. Floods are bounded by
`web/guard.py`.

What it does, point by point: docs/eyes.md, 'The renderer at a glance'.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.resources
import logging
import random
import socket
import tempfile
import time
import uuid
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import msgspec
from aiohttp import WSCloseCode, WSMsgType, web

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.eyes import kiosk, motion, placement, styles, wire
from buddybot.eyes.settings import EyeRendererSettings
from buddybot.runtime.config import resolve_path
from buddybot.runtime.endpoints import local_host, serve_failure
from buddybot.runtime.errors import UsageError
from buddybot.runtime.limits import clip
from buddybot.runtime.loop_inbox import LoopInbox
from buddybot.runtime.node import Node, RateLimitedLog
from buddybot.runtime.overrides import given, merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext
from buddybot.web.guard import (
    ANONYMOUS,
    IDLE_S,
    AcceptErrorLog,
    Guard,
    GuardedSite,
    ListenerWatch,
    evict_for,
    guard_for,
    origin_allowed,
    request_port,
)
from buddybot.web.page_outbox import PageOutbox

log = logging.getLogger("buddybot.eye-renderer")
_warn = RateLimitedLog(log)

PAGE_EYES = ("left", "right", "both")
STATIC = {"eyes.js": "application/javascript", "pose.js": "application/javascript",
          "draw.js": "application/javascript", "eyes.css": "text/css"}


def _eye_list(choice: str) -> list[str]:
    """`--eyes both` is the list of both eyes; `left`/`right` is a list of one."""
    return list(placement.EYES) if choice == "both" else [choice]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options overriding `[eye_renderer]` keys (defaults and ranges: settings.py), then
    the ones that only exist on the command line (browser flags, forced displays)."""
    struct = EyeRendererSettings
    settings_option(parser, "--host", struct=struct, field="host")
    settings_option(parser, "--port", struct=struct, field="port")
    settings_option(parser, "--no-browser", struct=struct, field="browser",
                    action="store_false", help="only serve the pages, open no kiosk windows")
    settings_option(parser, "--browser", struct=struct, field="browser_path", metavar="PATH")
    settings_option(parser, "--eyes", struct=struct, field="eyes",
                    choices=["left", "right", "both"], convert=_eye_list,
                    help="which eyes to show (empty list: both)")
    settings_option(parser, "--left-display", struct=struct, field="left_display",
                    metavar="N")
    settings_option(parser, "--right-display", struct=struct, field="right_display",
                    metavar="N")
    settings_option(parser, "--style", struct=struct, field="style", metavar="NAME")
    settings_option(parser, "--style-file", struct=struct, field="style_file", metavar="PATH")
    parser.add_argument("--browser-arg", action="append", default=[], metavar="ARG",
                        help="extra browser flag (repeatable), e.g. --browser-arg=--disable-gpu")
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


def placement_request(s: EyeRendererSettings) -> placement.Request:
    """The eye placement the merged settings ask for (0 means 'not configured')."""
    return placement.Request(eyes=tuple(s.eyes), left_display=s.left_display or None,
                             right_display=s.right_display or None)


class StartupError(UsageError):
    """The renderer cannot start as configured (exit status 2: not restarted)."""


def plan_windows(s: EyeRendererSettings, geometries: list[str]) -> list[placement.Window]:
    """The kiosk windows to open (empty when serving pages only).

    `geometries`: `--display WxH+X+Y` values, which replace the detected displays.
    """
    if not s.browser:
        return []
    request = placement_request(s)
    try:
        displays = [placement.parse_geometry(g) for g in geometries]
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

PAGE_WRITE_BUFFER = 16 * 1024
"""Bytes a page's sends may queue in the process before they wait for it to read
(asyncio's high-water mark and aiohttp's drain threshold, 256 KiB by default):
a second of eye traffic, and a bound on the memory a stuck page holds."""
SEND_BUFFER_MAX = 64 * 1024
"""Bytes queued to one page beyond which it is dropped at once (it stopped reading)."""
KERNEL_SEND_BUFFER = 32 * 1024
"""SO_SNDBUF of a page's socket: seconds of eye traffic even on Wi-Fi, and it
keeps the kernel from buffering megabytes for a page that never reads (which
would also hide the stall for a long time)."""
CLOSE_TIMEOUT_S = 2.0
"""How long a close handshake may take before the connection is cut."""


class Page(PageOutbox[str]):
    """One connected page: its outbox (newest message per slot) and its sender.

    The outbox is the page's whole send queue, so it is bounded by the number
    of slots (a handful) however fast samples arrive and however slowly the
    page reads: a page only ever needs the latest value of each topic.
    """

    def __init__(self, eye: str, transport: asyncio.Transport | None,
                 priority: int = ANONYMOUS) -> None:
        self.eye = eye
        self.outbox = wire.LatestState()
        super().__init__(transport, self.outbox.take, priority)

    def push(self, slot: str, text: str) -> None:
        self.outbox.put(slot, text)
        self.wake()


class Hub:
    """Current state plus the connected pages; used only on the event loop.

    It also holds what a live settings change may alter (`apply`): the looks
    every page gets, the page limit, the stall time and the allowed origins,
    each read where it is used so a change applies to the next use.
    """

    def __init__(self, hello: wire.Hello, max_pages: int = 16,
                 allowed_origins: tuple[str, ...] = (), stall_s: float = 2.0,
                 library: styles.StyleLibrary | None = None) -> None:
        self.library = library   # the styles a live `style` change may name
        self.state = wire.LatestState()
        self.pages: set[Page] = set()
        self.max_pages = max_pages
        self.allowed_origins = allowed_origins
        self.stall_s = stall_s
        self.hello = hello
        self.hello_text = wire.encode("hello", hello)
        self.bus = False
        self.state.put("status", wire.encode("status", wire.Status(bus=False)))
        self.messages = 0
        self.samples = 0     # from the bus (copied from the inbox), before coalescing
        self.dropped = 0     # pages cut because they stopped reading
        self.refused = 0     # connections over max_pages
        self.evicted = 0     # pages cut to make room for a new one
        self.forbidden = 0   # WebSockets from a foreign origin
        self.motion: motion.MotionScheduler | None = None   # set by `start_motion`
        self.motion_changed = asyncio.Event()   # the scheduler's plan may be sooner
        self.motion_events = 0
        self.pongs = 0

    def publish(self, msg: m.Message) -> None:
        self._push(wire.slot(msg), self.state.put_message(msg))
        self.messages += 1
        if self.motion is None:
            return
        if isinstance(msg, m.EyesDirection):
            self.send_motion(self.motion.set_direction(msg.yaw, msg.pitch, now_ms()))
        elif isinstance(msg, m.ScreenExpression):
            self.send_motion(self.motion.set_expression(int(msg.action), now_ms()))

    def start_motion(self, scheduler: motion.MotionScheduler) -> None:
        """Let `scheduler` decide the face's blinks and saccades (one per renderer)."""
        self.motion = scheduler

    def send_motion(self, events: list[motion.MotionEvent]) -> None:
        """Every page gets each event; the newest of each kind stays in the state,
        so a page that connects late joins the motion under way."""
        for event in events:
            text = wire.encode("motion", event)
            slot_name = wire.motion_slot(event.kind)
            self.state.put(slot_name, text)
            self._push(slot_name, text)
            self.motion_events += 1
        self.motion_changed.set()

    def pong(self, page: Page, t0: float) -> None:
        """Answer a page's clock ping with the server clock now (NTP-style)."""
        page.push("pong", wire.encode("pong", wire.Pong(t0=t0, server_ms=now_ms())))
        self.pongs += 1

    def apply(self, s: EyeRendererSettings) -> None:
        """Take the live fields of `s` (on the event loop). New looks go to every
        connected page at once as a fresh hello (a page restyles on any hello);
        the limits apply from the next connection or send. A lower `max_pages`
        cuts no page that is already connected."""
        self.max_pages = s.max_pages
        self.stall_s = s.page_stall_s
        self.allowed_origins = tuple(s.allowed_origins)
        style = self.library.get(s.style) if self.library is not None else self.hello.style
        hello = msgspec.structs.replace(self.hello, iris_color=s.iris_color,
                                        max_yaw_deg=s.max_yaw_deg,
                                        max_pitch_deg=s.max_pitch_deg, style=style)
        if hello != self.hello:
            self.hello = hello
            self.hello_text = wire.encode("hello", hello)
            self._push("hello", self.hello_text)
        if self.motion is not None:
            self.motion.configure(motion_config(s), now_ms())
            self.motion_changed.set()

    def publish_batch(self, batch: list[m.Message]) -> None:
        for msg in batch:
            self.publish(msg)

    def set_bus(self, up: bool) -> None:
        """Tell every page when the renderer gets on or falls off the bus."""
        if up == self.bus:
            return
        self.bus = up
        text = wire.encode("status", wire.Status(bus=up))
        self.state.put("status", text)
        self._push("status", text)

    def _push(self, slot: str, text: str) -> None:
        for page in self.pages:
            page.push(slot, text)

    @property
    def full(self) -> bool:
        return len(self.pages) >= self.max_pages

    def make_room(self, priority: int = ANONYMOUS) -> bool:
        """Whether a page of `priority` may join: a free slot, or one taken from
        a page it outranks or equals (idle ones, then the longest quiet, first:
        the kiosk pages ping every 2 s), cut now."""
        if not self.full:
            return True
        victim = evict_for(self.pages, priority, IDLE_S)
        if victim is None:
            return False
        self.leave(victim)
        if victim.cut():
            self.evicted += 1
            _warn.warning("evict", "page cut (eye=%s) to make room for a new one "
                          "(eye_renderer.max_pages)", victim.eye)
        return True

    def join(self, eye: str, transport: asyncio.Transport | None = None,
             priority: int = ANONYMOUS) -> Page:
        page = Page(eye, transport, priority)
        page.push("hello", self.hello_text)
        for slot, text in self.state.items():
            page.push(slot, text)
        self.pages.add(page)
        return page

    def leave(self, page: Page) -> None:
        self.pages.discard(page)

    def drop(self, page: Page, why: str) -> None:
        """Cut a page that stopped reading (counted and logged once per page)."""
        if page.cut():
            self.dropped += 1
            _warn.warning("stall", "page dropped (eye=%s): %s", page.eye, why)

    def health(self) -> dict[str, Any]:
        per_eye: dict[str, int] = {}
        for page in self.pages:
            per_eye[page.eye] = per_eye.get(page.eye, 0) + 1
        return {"clients": len(self.pages), "pages": per_eye, "max_pages": self.max_pages,
                "bus": self.bus, "samples": self.samples, "messages": self.messages,
                "dropped": self.dropped, "refused": self.refused, "evicted": self.evicted,
                "forbidden": self.forbidden,
                "motion_events": self.motion_events, "pongs": self.pongs}


_EPOCH_AT_ZERO_NS = time.time_ns() - time.monotonic_ns()


def now_ms() -> float:
    """The server clock every motion event and pong is on: ms since the epoch as read
    when the renderer started, advanced by the monotonic clock. A wall clock stepped
    later (NTP on a computer with no real-time clock) never moves a blink, and pages
    on this computer, whose clocks are monotonic, do not drift from it between pings."""
    return (_EPOCH_AT_ZERO_NS + time.monotonic_ns()) / 1e6


def motion_config(s: EyeRendererSettings) -> motion.MotionConfig:
    """The scheduler's knobs from the (live) settings."""
    return motion.MotionConfig(
        blink_interval_min_ms=1000.0 * s.blink_interval_min_s,
        blink_interval_max_ms=1000.0 * s.blink_interval_max_s,
        gaze_blink_deg=s.gaze_blink_deg, lead_ms=s.motion_lead_ms,
        max_yaw_deg=s.max_yaw_deg, max_pitch_deg=s.max_pitch_deg)


MOTION_IDLE_WAKE_S = 1.0
"""The motion timer's longest sleep (asleep, nothing is due): a bound, not a tick."""


async def run_motion(hub: Hub) -> None:
    """The motion timer: tick the hub's scheduler when its next decision is due,
    or sooner when an input changed its plan (`hub.motion_changed`)."""
    while hub.motion is not None:
        hub.motion_changed.clear()
        wait_s = (hub.motion.next_due_ms() - now_ms()) / 1000.0
        if wait_s > 0:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(min(wait_s, MOTION_IDLE_WAKE_S)):
                    await hub.motion_changed.wait()
            continue
        events = hub.motion.tick(now_ms())
        if events:
            hub.send_motion(events)


class Inbox(LoopInbox[m.Message]):
    """Samples from Zenoh's threads to the event loop, newest per slot.

    A sample only replaces the pending one of its slot and at most one
    wake-up is ever queued (`runtime.loop_inbox`), so the loop's work per turn
    is bounded by the number of slots, whatever the sample rate: handing
    each sample over on its own once gave pages 17 s old gaze. Batches are
    at least `min_interval_s` apart (2 ms: many times the page's frame rate).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop,
                 deliver: Callable[[list[m.Message]], None],
                 min_interval_s: float = 0.002) -> None:
        super().__init__(loop, deliver, min_interval_s)
        self._pending: dict[str, m.Message] = {}
        self.coalesced = 0   # samples replaced by a newer one before the loop saw them

    def put(self, msg: m.Message) -> None:
        """Called from Zenoh's threads."""
        slot = wire.slot(msg)
        with self._lock:
            self.received += 1
            if self._pending.pop(slot, None) is not None:
                self.coalesced += 1
            self._pending[slot] = msg   # re-inserted last: arrival order is kept
            self._schedule()

    def _take(self) -> list[m.Message]:
        batch = list(self._pending.values())
        self._pending.clear()
        return batch


async def _sender(ws: web.WebSocketResponse, page: Page, hub: Hub) -> None:
    """Flush the page's outbox whenever something new is in it.

    A page that stops reading is cut: its sends not draining within
    `hub.stall_s`, or more than SEND_BUFFER_MAX bytes waiting for it. A page
    that went away ends this task quietly (the reader side cleans up).
    """
    stalled = await page.send_until_closed(ws, ws.send_str, lambda: hub.stall_s, log,
                                           max_unsent=SEND_BUFFER_MAX)
    if stalled is not None:
        hub.drop(page, f"it has not read what was sent for {stalled:.1f} s")


def _read_static() -> dict[str, bytes]:
    folder = importlib.resources.files("buddybot.eyes") / "web"
    return {name: (folder / name).read_bytes() for name in ("eyes.html", *STATIC)}


def make_app(hub: Hub, guard: Guard) -> web.Application:
    """The web application: page, static files, WebSocket, health (the allowed
    origins and the stall time are the hub's, read on each use).

    No handler ever waits for a page's sends (each page has its own sender
    task), so `/healthz` and the pages are answered however busy or stuck
    the WebSockets are. Requests for a name the renderer is not served at
    get 421 (`guard`).
    """
    files = _read_static()
    sockets: set[web.WebSocketResponse] = set()

    async def index(_request: web.Request) -> web.StreamResponse:
        raise web.HTTPFound("/eyes?eye=both")

    async def page(request: web.Request) -> web.StreamResponse:
        eye = request.query.get("eye", "both")
        if eye not in PAGE_EYES:
            return web.Response(status=400, text=f"bad eye {clip(eye, 40)!r}: "
                                "use left, right or both\n")
        return web.Response(body=files["eyes.html"], content_type="text/html",
                            headers={"Cache-Control": "no-cache"})

    async def static(request: web.Request) -> web.StreamResponse:
        name = request.match_info["name"]
        if name not in STATIC:
            raise web.HTTPNotFound()
        return web.Response(body=files[name], content_type=STATIC[name],
                            headers={"Cache-Control": "no-cache"})

    async def health(_request: web.Request) -> web.StreamResponse:
        return web.json_response({**hub.health(), **guard.counters()})

    async def refuse(request: web.Request, reason: str) -> web.WebSocketResponse:
        """Accept the handshake only to close at once with code 1013 and `reason`
        (a browser shows close reasons, not HTTP error bodies)."""
        ws = web.WebSocketResponse(timeout=CLOSE_TIMEOUT_S)
        await ws.prepare(request)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(CLOSE_TIMEOUT_S):
                await ws.close(code=WSCloseCode.TRY_AGAIN_LATER, message=reason.encode())
        if request.transport is not None:
            request.transport.abort()
        return ws

    async def websocket(request: web.Request) -> web.StreamResponse:
        eye = request.query.get("eye", "both")
        if eye not in PAGE_EYES:
            return web.Response(status=400, text=f"bad eye {clip(eye, 40)!r}: "
                                "use left, right or both\n")
        origin = request.headers.get("Origin")
        if not origin_allowed(origin, guard.hosts_of(request.transport),
                              port=request_port(request.host),
                              listed=hub.allowed_origins):
            hub.forbidden += 1
            _warn.warning("origin", "refused a WebSocket from origin %s (not a name the "
                          "renderer is served at; eye_renderer.allowed_origins lists more)",
                          clip(origin, 80))
            return web.Response(status=403, text=f"origin {clip(origin, 80)} may not open "
                                "the eye WebSocket (see eye_renderer.allowed_origins)\n")
        if not hub.make_room(ANONYMOUS):
            hub.refused += 1
            _warn.warning("full", "refused a page: %d pages connected, the most allowed "
                          "(eye_renderer.max_pages)", len(hub.pages))
            return await refuse(request, f"too many pages ({hub.max_pages} max)")
        # No compression: messages are ~100 bytes, and each compressor costs a
        # page ~100s of KiB and CPU per message.
        ws = web.WebSocketResponse(heartbeat=5.0, timeout=CLOSE_TIMEOUT_S, compress=False,
                                   writer_limit=PAGE_WRITE_BUFFER)
        await ws.prepare(request)
        transport = request.transport
        sock = transport.get_extra_info("socket") if transport is not None else None
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, KERNEL_SEND_BUFFER)
        if isinstance(transport, asyncio.WriteTransport):
            transport.set_write_buffer_limits(high=PAGE_WRITE_BUFFER)
        client = hub.join(eye, transport if isinstance(transport, asyncio.Transport) else None,
                          ANONYMOUS)
        sockets.add(ws)
        sender = asyncio.create_task(_sender(ws, client, hub))
        log.info("page connected (eye=%s, %d pages)", eye, len(hub.pages))
        try:
            async for msg in ws:
                client.touch()
                if msg.type == WSMsgType.ERROR:
                    break
                # A page only says "ping" (clock sync); anything else is ignored.
                if msg.type == WSMsgType.TEXT:
                    t0 = wire.parse_ping(msg.data)
                    if t0 is not None:
                        hub.pong(client, t0)
        finally:
            hub.leave(client)
            sockets.discard(ws)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender
            # No pong in time: the page stopped reading, even when all that was
            # sent fit in the kernel's buffers; never keep data for a page that is gone.
            if isinstance(ws.exception(), TimeoutError):
                hub.drop(client, "it stopped answering pings")
            elif client.unsent():
                hub.drop(client, "it stopped answering with data still unsent")
            log.info("page left (eye=%s, %d pages)", eye, len(hub.pages))
        return ws

    async def close_sockets(_app: web.Application) -> None:
        for ws in list(sockets):
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(CLOSE_TIMEOUT_S):
                    await ws.close(code=WSCloseCode.GOING_AWAY, message=b"server shutdown")

    app = web.Application(middlewares=[guard.middleware()])
    app.router.add_get("/", index)
    app.router.add_get("/eyes", page)
    app.router.add_get("/static/{name}", static)
    app.router.add_get("/ws", websocket)
    app.router.add_get("/healthz", health)
    app.on_shutdown.append(close_sockets)
    return app


# --- the service ---------------------------------------------------------------------


def _subscribe(node: Node, inbox: Inbox) -> None:
    def forward(msg: Any, _key: str) -> None:
        inbox.put(msg)

    for topic in (keys.EYES_DIRECTION, keys.PUPIL, keys.LIDS, keys.EXPRESSION):
        node.subscribe(topic, forward, delivery="inline")


def _on_bus(node: Node) -> bool:
    """Whether the node has a router right now (pages show "connecting" otherwise)."""
    return node.connected()  # False as well while the node closes


async def serve(ctx: ServiceContext, host: str, port: int,
                windows: list[placement.Window], browser: str | None) -> None:
    """Serve the pages first, then join the bus.

    The HTTP server starts before the Zenoh node, so with the router down
    (or still starting) the pages load and show their "connecting" face
    instead of a browser error, and kiosk windows open at once.
    """
    s = settings_from(ctx)
    library = load_styles(ctx, s)
    hub = Hub(wire.Hello(iris_color=s.iris_color, max_yaw_deg=s.max_yaw_deg,
                         max_pitch_deg=s.max_pitch_deg, server_id=uuid.uuid4().hex[:8],
                         style=library.get(s.style)),
              s.max_pages, tuple(s.allowed_origins), s.page_stall_s, library)
    guard = guard_for(s, host, log)
    accept_log = AcceptErrorLog(log).install(asyncio.get_running_loop())
    runner = web.AppRunner(make_app(hub, guard), access_log=None)
    await runner.setup()
    site = GuardedSite(runner, host, port, guard)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise StartupError(serve_failure(host or "0.0.0.0", port,
                                         str(exc.strerror or exc))) from None
    actual = runner.addresses[0][1] if runner.addresses else port
    watch = ListenerWatch(site.listener)
    ctx.alive_checks.append(watch.alive)
    base = f"http://{local_host(host)}:{actual}"
    loop = asyncio.get_running_loop()
    inbox = Inbox(loop, hub.publish_batch)
    hub.start_motion(motion.MotionScheduler(motion_config(s), random.Random(), now_ms()))
    motion_timer = asyncio.create_task(run_motion(hub))
    print(f"eye renderer serving {base}/eyes?eye=both", flush=True)
    log.info("eyes: %s/eyes?eye=left|right|both", base)

    kiosks: list[kiosk.KioskWindow] = []
    profiles = tempfile.TemporaryDirectory(prefix="buddybot-eyes-")
    opening = asyncio.create_task(ctx.node_in_thread())
    node: Node | None = None
    try:
        for win in windows:
            assert browser is not None
            argv = kiosk.command(browser, kiosk.page_url(base, win.eye), win,
                                 Path(profiles.name) / win.eye, ctx.args.browser_arg)
            window = kiosk.KioskWindow(argv, f"{win.eye} eye on display {win.display_number}")
            window.start()
            kiosks.append(window)
        while not ctx.stop.is_set():
            await asyncio.sleep(0.2)
            for window in kiosks:
                window.poll()
            if node is None and opening.done():
                node = opening.result()
                if node is None:
                    break
                _subscribe(node, inbox)
                LiveSettings(s, partial(_apply_on_loop, loop, hub, library)).serve(node)
                node.diagnostics.values.update(where_served(base, host))
            if node is None:
                continue
            hub.samples = inbox.received
            hub.set_bus(_on_bus(node))
            diag = node.diagnostics
            diag.values["pages"] = len(hub.pages)
            diag.values["messages"] = hub.messages
            diag.values["windows"] = len(kiosks)
            diag.values["pages_dropped"] = hub.dropped
            diag.values["pages_refused"] = hub.refused
            diag.values["origins_refused"] = hub.forbidden
            diag.values["samples_coalesced"] = inbox.coalesced
            diag.values["motion_events"] = hub.motion_events
            diag.values["pages_evicted"] = hub.evicted
            diag.values["accept_errors"] = accept_log.accept_errors
            diag.values.update(guard.counters())
            if not watch.alive():
                diag.set("ERROR", f"not serving the eye pages: {watch.dead}")
    finally:
        ctx.stop.set()   # a node still waiting for its router gives up
        motion_timer.cancel()
        for window in kiosks:
            window.stop()
        await runner.cleanup()
        profiles.cleanup()
        if node is None:
            with contextlib.suppress(Exception):
                node = await opening
        if node is not None:
            node.close()


def _apply_on_loop(loop: asyncio.AbstractEventLoop, hub: Hub, library: styles.StyleLibrary,
                   new: EyeRendererSettings) -> None:
    """`LiveSettings`' callback (a node worker thread): hand the change to the
    event loop, which owns the hub. Not waited for: the loop takes it within
    one turn; a loop that is closing refuses it (RuntimeError -> not applied).
    A style nobody knows is refused here, before anything changes (ConfigError
    naming the known ones)."""
    library.get(new.style)
    loop.call_soon_threadsafe(hub.apply, new)


def load_styles(ctx: ServiceContext, s: EyeRendererSettings) -> styles.StyleLibrary:
    """The built-in styles plus `style_file`'s (read once: restart-only), and
    `style` checked against them: a bad file or an unknown style is a
    ConfigError naming the key (exit status 2)."""
    path = None
    if s.style_file:
        path = resolve_path(ctx.config, s.style_file,
                            from_command_line=given(ctx.args, EyeRendererSettings,
                                                    "style_file"))
    library = styles.load(path)
    library.get(s.style)
    return library


def where_served(base: str, listen_host: str) -> dict[str, str]:
    """Diagnostics values saying where the pages are, for `buddybot doctor` on any
    host: `url` as this host reaches them (loopback when serving every
    interface), the configured `listen_host` and this machine's `hostname`."""
    return {"url": base, "listen_host": listen_host, "hostname": socket.gethostname()}


def settings_from(ctx: ServiceContext) -> EyeRendererSettings:
    """`[eye_renderer]` with the command line on top: what `run` and `serve` use.

    `--host ""` (every interface) is a value like any other, and `--port`
    out of 0..65535 is refused by `merge` naming the flag.
    """
    return merge(ctx.config.section(EyeRendererSettings), ctx.args)


def run(ctx: ServiceContext) -> int:
    s = settings_from(ctx)
    load_styles(ctx, s)   # a bad style or style file: exit 2 before any window opens
    windows = plan_windows(s, ctx.args.display)  # StartupError: exit 2 (run_main)
    browser = None
    if windows:
        browser = kiosk.find_browser(s.browser_path)
        if browser is None:
            raise StartupError(
                "no Chromium found for the kiosk windows: install it (scripts/chromium.sh), "
                "set eye_renderer.browser_path, or run with --no-browser")
    asyncio.run(serve(ctx, s.host, s.port, windows, browser))
    return 0
