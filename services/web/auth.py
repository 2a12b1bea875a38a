"""Who may operate the robot's web surfaces: per-robot secrets, session cookies, tokens.

On loopback a surface asks for nothing; beyond it, for a secret: one per
role (`operator`, `viewer`, `foxglove`), each an owner-only file in the
state folder (`state_dir`), and session cookies signed with it, so rotating
or revoking a secret ends its sessions (docs/dashboard.md, "Opening it
from a laptop").
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import os
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from buddybot.runtime.endpoints import is_loopback
from buddybot.runtime.errors import BuddyBotError
from buddybot.runtime.private_files import (
    NotPrivate,
    read_private,
    secret_file,
    write_private,
)
from buddybot.runtime.private_files import (
    state_dir as state_dir,  # the web surfaces name it from here
)

ROLES = ("operator", "viewer", "foxglove")
"""Every secret there is; `operator` and `viewer` log in to the dashboard."""
LOGIN_ROLES = ("operator", "viewer")
COOKIE = "buddybot_session"
MAX_SECRET_CHARS = 256
"""Longer login input is refused before it is compared."""
SECRET_BYTES = 32


class SecretError(BuddyBotError):
    """A secret file that cannot be used (not ours, readable by others, not a file)."""


def secret_path(role: str, folder: Path | None = None) -> Path:
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}: one of {', '.join(ROLES)}")
    return secret_file(role, folder)


def login_required(host: str, mode: str) -> bool:
    """True unless the surface is served on loopback only and `mode` is "auto"
    ("" and 0.0.0.0 are every interface; a name other than localhost may
    resolve anywhere, so it counts as beyond loopback)."""
    return mode == "always" or not is_loopback(host)


# --- the files ----------------------------------------------------------------------


def read_secret(path: Path) -> str | None:
    """The secret in `path`; None when revoked (empty) or absent; SecretError when unusable."""
    try:
        data = read_private(path, MAX_SECRET_CHARS, "rotate the secret "
                            "(`buddybot secret rotate`), then chmod 600 it")
    except NotPrivate as exc:
        raise SecretError(str(exc)) from None
    if data is None:
        return None
    text = data.decode("ascii", "replace").strip()
    if len(text) > MAX_SECRET_CHARS:
        raise SecretError(f"{path} holds more than {MAX_SECRET_CHARS} characters: not a secret")
    return text or None


def write_secret(path: Path, text: str) -> None:
    """Replace `path` atomically with `text` (owner-only; "" revokes)."""
    write_private(path, (text + "\n" if text else "").encode())


def new_secret() -> str:
    return secrets.token_urlsafe(SECRET_BYTES)


def ensure_secret(path: Path) -> bool:
    """Make the secret on first start (True when made); a revoked one stays revoked."""
    if path.exists() or path.is_symlink():
        read_secret(path)  # refuses a file others may read
        return False
    write_secret(path, new_secret())
    return True


def ensure_operator_secret(who: str) -> None:
    """Make the operator secret on first start of a program that operates for a
    person (the dashboard, Foxglove): the arbiter grants priority `operator` and
    breaks leases only for it. ConfigError-worthy problems raise SecretError."""
    path = secret_path("operator")
    try:
        made = ensure_secret(path)
    except OSError as exc:
        raise SecretError(f"cannot make the operator secret {path}: {exc.strerror}") from None
    if made:
        print(f"{who}: made the operator secret in {path} (`buddybot secret show` "
              "prints it)", flush=True)


class SecretStore:
    """The role secrets of one state folder, re-read when a file changes.

    A `stat` per check is the cost of noticing `rotate`/`revoke` at once."""

    def __init__(self, folder: Path, roles: tuple[str, ...] = LOGIN_ROLES) -> None:
        self.folder = folder
        self.roles = roles
        self._seen: dict[str, tuple[tuple[int, int, int] | None, str | None]] = {}

    def ensure(self) -> list[str]:
        """Make missing secrets; the roles made."""
        return [r for r in self.roles if ensure_secret(secret_path(r, self.folder))]

    def current(self) -> dict[str, str | None]:
        out: dict[str, str | None] = {}
        for role in self.roles:
            path = secret_path(role, self.folder)
            try:
                st = os.stat(path, follow_symlinks=False)
                sig: tuple[int, int, int] | None = (st.st_ino, st.st_mtime_ns, st.st_size)
            except FileNotFoundError:
                sig = None
            seen = self._seen.get(role)
            if seen is None or seen[0] != sig:
                try:
                    value = read_secret(path) if sig is not None else None
                except SecretError:
                    value = None  # unusable: no one of this role gets in
                seen = (sig, value)
                self._seen[role] = seen
            out[role] = seen[1]
        return out


# --- the rules (pure) ---------------------------------------------------------------


def login_role(given: str, current: Mapping[str, str | None]) -> str | None:
    """The role whose secret `given` is; None for anything else (compared in constant time)."""
    if not given or len(given) > MAX_SECRET_CHARS:
        return None
    found = None
    for role in LOGIN_ROLES:
        want = current.get(role)
        if want and hmac.compare_digest(given.encode(), want.encode()):
            found = role
    return found


def _mac(secret: str, body: str) -> str:
    digest = hmac.new(secret.encode(), body.encode(), hashlib.sha256).digest()
    return base64.urlsafe_b64encode(digest).decode().rstrip("=")


@dataclass(frozen=True)
class Session:
    role: str
    expires: int
    nonce: str = ""
    """The cookie's own random part: what a logout ends."""


def make_cookie(role: str, secret: str, now: float, lifetime_s: float) -> str:
    """`role.expires.nonce.mac`, signed with the role's secret."""
    body = f"{role}.{int(now + lifetime_s)}.{secrets.token_urlsafe(12)}"
    return f"{body}.{_mac(secret, body)}"


def check_cookie(value: str | None, current: Mapping[str, str | None],
                 now: float) -> Session | None:
    """The session a cookie proves; None when it is forged, expired or its secret changed."""
    if not value or len(value) > 512:
        return None
    parts = value.split(".")
    if len(parts) != 4:
        return None
    role, expires, nonce, mac = parts
    secret = current.get(role) if role in LOGIN_ROLES else None
    if not secret or not expires.isdigit():
        return None
    if not hmac.compare_digest(mac, _mac(secret, ".".join(parts[:3]))):
        return None
    if int(expires) < now:
        return None
    return Session(role, int(expires), nonce)


def token_ok(given: str | None, want: str | None) -> bool:
    """A bearer token (the Foxglove bridge's) against its secret; False when revoked."""
    if not want or not given or len(given) > MAX_SECRET_CHARS:
        return False
    return hmac.compare_digest(given.encode(), want.encode())
