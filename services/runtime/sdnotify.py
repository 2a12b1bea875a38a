"""systemd's readiness and watchdog protocol (sd_notify), without libsystemd.

A `Type=notify` unit is "started" only when its process says `READY=1`, and a
unit with `WatchdogSec=` is killed and restarted when its process stops saying
`WATCHDOG=1` in time. Both are one datagram to the AF_UNIX socket systemd names
in `$NOTIFY_SOCKET` (a leading `@` means Linux's abstract namespace). Outside
systemd the variable is unset and every call is a no-op, so services call these
unconditionally. Sending never raises: a robot must not stop because its
supervisor's socket went away.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping

log = logging.getLogger("buddybot.sdnotify")


def socket_address(value: str | None) -> str | bytes | None:
    """The address to send to, from `$NOTIFY_SOCKET`; None when unset or unusable.

    `@name` is the abstract socket `\\0name`; a path must be absolute (systemd
    also allows `vsock:` addresses, for virtual machines, which we do not need).
    """
    if not value:
        return None
    if value.startswith("@"):
        return b"\0" + value[1:].encode()
    if value.startswith("/"):
        return value
    return None


def watchdog_period_s(env: Mapping[str, str], pid: int) -> float | None:
    """How often to send `WATCHDOG=1`: half of `$WATCHDOG_USEC`, or None when the
    watchdog is off or meant for another process (`$WATCHDOG_PID` differs).

    Half the timeout leaves a whole period of slack for a slow machine.
    """
    raw = env.get("WATCHDOG_USEC", "")
    owner = env.get("WATCHDOG_PID", "")
    if not raw.isdigit() or int(raw) == 0:
        return None
    if owner and (not owner.isdigit() or int(owner) != pid):
        return None
    return int(raw) / 1e6 / 2


class Notifier:
    """Sends sd_notify states to one socket (or nowhere)."""

    def __init__(self, address: str | bytes | None, watchdog_s: float | None = None) -> None:
        self.address = address
        self.watchdog_s = watchdog_s
        # Opened once, up front: the watchdog timer and the main thread share it.
        self._sock: socket.socket | None = None
        if address is not None:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)

    @classmethod
    def from_env(cls, env: Mapping[str, str] | None = None) -> Notifier:
        """The notifier systemd set up for this process (a no-op one outside systemd)."""
        env = os.environ if env is None else env
        address = socket_address(env.get("NOTIFY_SOCKET"))
        return cls(address, watchdog_period_s(env, os.getpid()) if address else None)

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def notify(self, state: str) -> bool:
        """Send `state` (e.g. `READY=1`); True if the datagram left."""
        if self.address is None or self._sock is None:
            return False
        try:
            self._sock.sendto(state.encode(), self.address)
        except OSError as exc:  # systemd gone or restarting: nothing to tell it
            log.debug("sd_notify %r to %r failed: %s", state, self.address, exc)
            return False
        return True

    def ready(self, status: str = "") -> bool:
        """Tell systemd start-up is complete (and, optionally, a status line)."""
        return self.notify("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def watchdog(self) -> bool:
        """One keep-alive ping."""
        return self.notify("WATCHDOG=1")

    def stopping(self) -> bool:
        return self.notify("STOPPING=1")

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
