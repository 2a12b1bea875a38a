"""The Foxglove bridge's token beyond loopback: who may open the bridge at all.

The SDK's server has no hook on the handshake, so the gate (`gate.py`)
asks this module about each request head: served beyond loopback (or
`[foxglove] login = "always"`) a client must bring the robot's `foxglove`
secret (`buddybot secret show foxglove`) as `?token=...` in the
connection URL (what the Foxglove app can send: it keeps the URL's query)
or as `Authorization: Bearer ...` (programs). Rotating or revoking the
secret refuses new connections and ends open ones within `RECHECK_S`.
"""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

from buddybot.runtime.errors import ConfigError
from buddybot.web import auth as web_auth

RECHECK_S = 1.0
"""How often an open connection's token is compared with the secret again."""
ROLE = "foxglove"


def given_token(head: bytes, fields: dict[str, str]) -> str | None:
    """The token a request head carries (query `token`, else a Bearer header)."""
    line = head.split(b"\r\n", 1)[0].decode("latin-1")
    parts = line.split(" ")
    if len(parts) >= 2:
        found = parse_qs(urlsplit(parts[1]).query).get("token")
        if found:
            return found[0]
    auth = fields.get("authorization", "")
    scheme, _, value = auth.partition(" ")
    return value.strip() if scheme.lower() == "bearer" and value.strip() else None


class TokenCheck:
    """The `foxglove` secret of one state folder (re-read when the file changes)."""

    def __init__(self, store: web_auth.SecretStore) -> None:
        self.store = store
        self.refused = 0

    def current(self) -> str | None:
        return self.store.current().get(ROLE)

    def allows(self, given: str | None) -> bool:
        return web_auth.token_ok(given, self.current())


def token_check(host: str, mode: str) -> TokenCheck | None:
    """The check when the bridge serves beyond loopback (None: no token asked);
    the secret is made on first start."""
    if not web_auth.login_required(host, mode):
        return None
    store = web_auth.SecretStore(web_auth.state_dir(), roles=(ROLE,))
    try:
        made = store.ensure()
    except (web_auth.SecretError, OSError) as exc:
        raise ConfigError(f"Foxglove bridge token: {exc}") from None
    if made:
        print(f"foxglove bridge: made its token in "
              f"{web_auth.secret_path(ROLE, store.folder)} "
              f"(`buddybot secret show foxglove` prints it)", flush=True)
    return TokenCheck(store)
