"""The Zenoh session of a BuddyBot process: its configuration and its opening.

Written once for every process (services, probes, the router): explicit
endpoints, multicast scouting off, clients that wait for their router and
reconnect quickly, a stalled link closed after 100 ms instead of 5 s, and
no message larger than the largest image we accept.
"""

from __future__ import annotations

import json
import logging
import threading
from typing import Any, Literal

import zenoh
import zenoh.ext

from buddybot.core import keys
from buddybot.core.errors import ConfigError

log = logging.getLogger("buddybot.node")


# --- session configuration ------------------------------------------------------

WAIT_BEFORE_CLOSE_US = 100_000
"""Zenoh's `wait_before_close` (microseconds) for router and clients."""
MAX_MESSAGE_BYTES = keys.IMAGE_MESSAGE_BYTES
"""Zenoh's `max_message_size`: nothing larger than the largest image we accept."""


def zenoh_config(
    *,
    mode: Literal["client", "peer", "router"] = "client",
    connect: list[str] | tuple[str, ...] = (),
    listen: list[str] | tuple[str, ...] = (),
    base_file: str | None = None,
) -> zenoh.Config:
    """A Zenoh config with BuddyBot's rules: explicit endpoints, no multicast
    scouting, clients that wait for their router and reconnect quickly."""
    try:
        config = zenoh.Config.from_file(base_file) if base_file else zenoh.Config()
    except zenoh.ZError as exc:  # exit status 2 (systemd units do not restart on it)
        raise ConfigError(f"{base_file}: not a valid Zenoh config: {exc}") from None
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    # A link that stays blocked this long is closed instead of holding back
    # every other stream behind one stalled reader (5 s by default; measured:
    # only this removed the radar gaps when one client was SIGSTOPped).
    config.insert_json5(
        "transport/link/tx/queue/congestion_control/block/wait_before_close",
        str(WAIT_BEFORE_CLOSE_US),
    )
    config.insert_json5("transport/link/rx/max_message_size", str(MAX_MESSAGE_BYTES))
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if mode != "router":
        # Wait for the router forever (services start in any order) and retry
        # fast, so a router restart costs ~0.2 s instead of ~4 s.
        config.insert_json5("connect/timeout_ms", "-1")
        config.insert_json5("connect/retry", '{"period_init_ms": 100, "period_max_ms": 500}')
    return config


def open_session(
    config: zenoh.Config, stop: threading.Event, what: str = "router"
) -> zenoh.Session | None:
    """Open a session in a helper thread so the caller stays responsive to a
    stop request while Zenoh waits for the router. None when stopped first."""
    result: dict[str, Any] = {}
    done = threading.Event()

    def opener() -> None:
        try:
            result["session"] = zenoh.open(config)
        except Exception as exc:  # zenoh raises ZError
            result["error"] = exc
        done.set()

    threading.Thread(target=opener, name="zenoh-open", daemon=True).start()
    waited = 0.0
    while not done.wait(0.1):
        if stop.is_set():
            return None
        waited += 0.1
        if abs(waited - 2.0) < 0.05 or (waited > 2 and int(waited * 10) % 100 == 0):
            log.warning("waiting for the Zenoh %s (%.0f s so far)...", what, waited)
    if "error" in result:
        raise ConnectionError(f"cannot open Zenoh session: {result['error']}")
    session: zenoh.Session = result["session"]
    return session


def live_instances(session: zenoh.Session, key: str, timeout: float = 2.0) -> set[str]:
    """Instance ids of the liveliness tokens matching `key` (`.../nodes/<name>/*`)."""
    found: set[str] = set()
    for reply in session.liveliness().get(key, timeout=timeout):
        if reply.ok is None:
            continue
        parts = keys.split_absolute(str(reply.ok.key_expr))
        match = keys.NODES.match(parts[1]) if parts else None
        if match is not None:
            found.add(match["instance"])
    return found
