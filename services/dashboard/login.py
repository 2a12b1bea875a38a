"""The dashboard's login beyond loopback: the login page, the session cookie, the gate.

The rules (secrets, signing, roles) are `buddybot.web.auth`; this
module is their HTTP side. A page without a valid session is sent to
`/login` (the page) or refused with 401 (the WebSocket, static files); a
viewer's session may watch, and `App.command` refuses it every button.
The cookie is HttpOnly and SameSite=Strict (another site's page never
sends it), and Secure when the dashboard serves HTTPS.
"""

from __future__ import annotations

import html
import importlib.resources
import logging
import time

from aiohttp import web

from buddybot.runtime.limits import clip
from buddybot.runtime.node import RateLimitedLog
from buddybot.web import auth as web_auth
from buddybot.web.guard import HostAllowList, origin_allowed, request_port

log = logging.getLogger("buddybot.dashboard")
_warn = RateLimitedLog(log)

OPERATOR = "operator"
VIEWER = "viewer"
PRIORITY = {OPERATOR: 2, VIEWER: 1}
"""Page-slot priority of a logged-in page (above `web.guard.ANONYMOUS`): an
operator can always get a slot, taken from a viewer's or an idle page's."""
MAX_FORM_BYTES = 4096
MAX_ENDED = 100_000
"""Logged-out sessions remembered until their cookies expire (each needed a login)."""


class Gate:
    """Who a request is; the login and logout routes."""

    def __init__(self, store: web_auth.SecretStore, secure: bool, lifetime_s: float,
                 hosts: HostAllowList | None = None) -> None:
        self.store = store
        self.hosts = hosts
        """The names the dashboard is served at: a login form posted from any other
        page's origin is refused (the same rule as the WebSocket's)."""
        self.secure = secure
        self.lifetime_s = lifetime_s
        self.refused_logins = 0
        self._ended: dict[str, int] = {}
        """Nonce -> expiry of every session logged out: its cookie no longer holds."""
        self._page = (importlib.resources.files("buddybot.dashboard") / "web" /
                      "login.html").read_text()

    def session(self, cookie: str | None) -> web_auth.Session | None:
        found = web_auth.check_cookie(cookie, self.store.current(), time.time())
        return None if found is None or found.nonce in self._ended else found

    def role(self, request: web.Request) -> str | None:
        found = self.session(request.cookies.get(web_auth.COOKIE))
        return None if found is None else found.role

    def add_routes(self, app: web.Application) -> None:
        app.router.add_get("/login", self.login_page)
        app.router.add_post("/login", self.login)
        app.router.add_post("/logout", self.logout)

    def _form(self, error: str, status: int) -> web.Response:
        body = self._page.replace("{error}", html.escape(error))
        return web.Response(text=body, status=status, content_type="text/html",
                            headers={"Cache-Control": "no-store"})

    async def login_page(self, _request: web.Request) -> web.StreamResponse:
        return self._form("", 200)

    async def login(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if not origin_allowed(origin, self.hosts, port=request_port(request.host)):
            return web.Response(status=403, text="log in from the dashboard's own page\n")
        if (request.content_length or 0) > MAX_FORM_BYTES:
            return web.Response(status=413, text="login form too large\n")
        try:
            form = await request.post()
        except (ValueError, web.HTTPException) as exc:  # a body that is no form
            self.refused_logins += 1
            return web.Response(status=400, text=f"bad login form: {clip(exc, 120)}\n")
        given = form.get("secret")
        role = web_auth.login_role(given if isinstance(given, str) else "",
                                   self.store.current())
        if role is None:
            self.refused_logins += 1
            _warn.warning("login", "refused a login from %s (wrong or revoked secret)",
                          clip(request.remote, 60))
            return self._form("Wrong secret (or it was revoked).", 401)
        secret = self.store.current()[role]
        assert secret is not None
        log.info("%s logged in from %s", role, clip(request.remote, 60))
        reply = web.HTTPSeeOther("/")
        reply.set_cookie(web_auth.COOKIE,
                         web_auth.make_cookie(role, secret, time.time(), self.lifetime_s),
                         max_age=int(self.lifetime_s), path="/", httponly=True,
                         samesite="Strict", secure=self.secure)
        return reply

    async def logout(self, request: web.Request) -> web.StreamResponse:
        """End the session on the server too: its cookie, copied or not, no longer
        holds, and its open pages are cut (`end_stale_sessions`)."""
        found = self.session(request.cookies.get(web_auth.COOKIE))
        if found is not None:
            now = time.time()
            self._ended = {n: t for n, t in self._ended.items() if t >= now}
            if len(self._ended) >= MAX_ENDED:  # never reached by people logging in
                self._ended.pop(next(iter(self._ended)))
            self._ended[found.nonce] = found.expires
            log.info("%s logged out from %s", found.role, clip(request.remote, 60))
        reply = web.HTTPSeeOther("/login")
        reply.del_cookie(web_auth.COOKIE, path="/")
        return reply
