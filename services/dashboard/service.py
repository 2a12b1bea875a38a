"""`buddybot run dashboard`: a live web page of what the robot perceives.

One aiohttp server per robot serves the page (`web/`, no build step) and one
WebSocket (`/ws`) that streams JSON (and the camera image as binary frames)
to every connected page. The server is the page's only door to the bus: it
holds one Node, subscribes to what the page shows, and does the buttons'
bus work under an operator lease taken from the controller. The dashboard
never publishes `eyes/expression` itself: the controller is its one
publisher. This module holds the options and the order of things (the
HTTP server starts before the node); `bus.py`, `pages.py`, `model.py` and
`login.py` hold the parts.

The parts and their rules: docs/dashboard.md, 'The service's parts'.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import ssl
import time
from functools import partial

from aiohttp import web

from buddybot.dashboard import login, radar_map
from buddybot.dashboard.bus import Bus, Mailbox
from buddybot.dashboard.pages import App, Board
from buddybot.dashboard.settings import DashboardSettings
from buddybot.runtime import enabled, registry
from buddybot.runtime.config import resolve_path
from buddybot.runtime.endpoints import local_host, serve_failure
from buddybot.runtime.errors import ConfigError, ServeError
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext
from buddybot.web import auth as web_auth
from buddybot.web.guard import (
    AcceptErrorLog,
    Guard,
    GuardedSite,
    ListenerWatch,
    guard_for,
)

log = logging.getLogger("buddybot.dashboard")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options overriding `[dashboard]` keys (defaults and ranges: settings.py)."""
    struct = DashboardSettings
    settings_option(parser, "--host", struct=struct, field="host")
    settings_option(parser, "--port", struct=struct, field="port")
    settings_option(parser, "--camera", struct=struct, field="camera")
    settings_option(parser, "--max-image-fps", struct=struct, field="max_image_fps")
    settings_option(parser, "--history-s", struct=struct, field="history_s")
    settings_option(parser, "--eye-url", struct=struct, field="eye_url", metavar="URL")
    settings_option(parser, "--eye-port", struct=struct, field="eye_port", metavar="PORT")
    settings_option(parser, "--login", struct=struct, field="login")
    settings_option(parser, "--tls-cert", struct=struct, field="tls_cert", metavar="FILE")
    settings_option(parser, "--tls-key", struct=struct, field="tls_key", metavar="FILE")


def settings_from(ctx: ServiceContext) -> DashboardSettings:
    """`[dashboard]` with the command line on top (0 and "" are values)."""
    return merge(ctx.config.section(DashboardSettings), ctx.args)


# --- the service -----------------------------------------------------------------------


def _other_tables(ctx: ServiceContext, s: DashboardSettings) -> tuple[int, dict[str, str]]:
    """The eye renderer's port (`eye_port`, else `[eye_renderer] port`) and the
    configured sounds, from this machine's config (tables read by name: the
    dashboard imports no other area)."""
    eye = getattr(ctx.config, "eye_renderer", None)
    audio = getattr(ctx.config, "audio", None)
    port = s.eye_port or int(getattr(eye, "port", 8080))
    sounds = dict(getattr(audio, "sounds", {}) or {})
    return port, sounds


def tls_context(ctx: ServiceContext, s: DashboardSettings) -> ssl.SSLContext | None:
    """The HTTPS context of `tls_cert`/`tls_key` (None: plain HTTP); ConfigError when unusable."""
    if bool(s.tls_cert) != bool(s.tls_key):
        raise ConfigError("[dashboard] tls_cert and tls_key go together: set both or neither")
    if not s.tls_cert:
        return None
    cert = resolve_path(ctx.config, s.tls_cert)
    key = resolve_path(ctx.config, s.tls_key)
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        context.load_cert_chain(cert, key)
    except (OSError, ssl.SSLError) as exc:
        raise ConfigError(f"[dashboard] tls_cert {cert} / tls_key {key}: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None
    return context


def make_gate(s: DashboardSettings, secure: bool, guard: Guard) -> login.Gate | None:
    """The login gate when the page is served beyond loopback (or `login = "always"`);
    the secrets are made on first start."""
    if not web_auth.login_required(s.host, s.login):
        return None
    store = web_auth.SecretStore(web_auth.state_dir())
    try:
        made = store.ensure()
    except (web_auth.SecretError, OSError) as exc:
        raise ConfigError(f"dashboard login secrets: {exc}") from None
    for role in made:
        print(f"dashboard: made the {role} secret in {web_auth.secret_path(role, store.folder)} "
              f"(`buddybot secret show {role}` prints it)", flush=True)
    return login.Gate(store, secure, s.session_hours * 3600.0, guard.hosts)


async def serve(ctx: ServiceContext, s: DashboardSettings) -> None:
    """Serve the page first, then join the bus; until SIGINT/SIGTERM."""
    eye_port, sounds = _other_tables(ctx, s)
    board = Board(s, eye_port, sorted(sounds), radar_map.Configured.read(ctx.config),
                  keep=enabled.node_names(ctx.config, registry.available_services()))
    tls = tls_context(ctx, s)
    guard = guard_for(s, s.host, log)
    accept_log = AcceptErrorLog(log).install(asyncio.get_running_loop())
    try:
        web_auth.ensure_operator_secret("dashboard")  # its lease is an operator's
    except web_auth.SecretError as exc:
        raise ConfigError(str(exc)) from None
    app = App(board, guard, make_gate(s, tls is not None, guard))
    runner = web.AppRunner(app.make(), access_log=None)
    await runner.setup()
    site = GuardedSite(runner, s.host or None, s.port, guard, ssl_context=tls)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise ServeError(serve_failure(s.host or "0.0.0.0", s.port,
                                       str(exc.strerror or exc))) from None
    port = runner.addresses[0][1] if runner.addresses else s.port
    watch = ListenerWatch(site.listener)
    ctx.alive_checks.append(watch.alive)
    scheme = "https" if tls else "http"
    print(f"dashboard serving {scheme}://{local_host(s.host)}:{port}/"
          f"{' (login required)' if app.gate else ''}", flush=True)

    loop = asyncio.get_running_loop()
    mailbox = Mailbox(loop, board.deliver)
    opening = asyncio.create_task(ctx.node_in_thread())
    node: Node | None = None

    def pages_changed(count: int) -> None:
        if app.bus is not None:
            app.bus.watch_images(count > 0)

    board.on_pages_changed = pages_changed
    last_page = time.monotonic()
    try:
        while not ctx.stop.is_set():
            await asyncio.sleep(0.2)
            if board.pages:
                last_page = time.monotonic()
            if node is None and opening.done():
                node = opening.result()
                if node is None:
                    break
                app.bus = Bus(node, s, mailbox, sounds)
                LiveSettings(s, partial(_apply, loop, app.bus, board)).serve(node)
                pages_changed(len(board.pages))
            if node is None:
                continue
            board.set_bus(node.connected())
            board.refresh_map()
            await app.end_stale_sessions()
            quiet_s = time.monotonic() - last_page
            bus = app.bus
            if bus is not None and not board.pages and bus.lease.lease_id is not None:
                await asyncio.to_thread(bus.release_idle, quiet_s)
            d = node.diagnostics.values
            d["pages"] = len(board.pages)
            d["images_sent"] = board.images_sent
            d["bad_requests"] = board.bad_requests
            d["pages_refused"] = board.refused
            d["origins_refused"] = board.forbidden
            d["samples"] = mailbox.received
            d["pages_evicted"] = board.evicted
            d["accept_errors"] = accept_log.accept_errors
            d.update(guard.counters())
            if not watch.alive():
                node.diagnostics.set("ERROR", f"not serving pages: {watch.dead}")
    finally:
        ctx.stop.set()
        await runner.cleanup()
        if node is None:
            with contextlib.suppress(Exception):
                node = await opening
        if node is not None:
            if app.bus is not None:
                await asyncio.to_thread(app.bus.close)
            node.close()


def _apply(loop: asyncio.AbstractEventLoop, bus: Bus, board: Board,
           new: DashboardSettings) -> None:
    """`LiveSettings`' callback (a node worker thread): the bus side takes the
    change at once, the pages' side on the event loop that owns it."""
    bus.apply(new)
    loop.call_soon_threadsafe(board.apply, new)


def run(ctx: ServiceContext) -> int:
    s = settings_from(ctx)
    asyncio.run(serve(ctx, s))
    return 0

