"""Kiosk browser windows, one per planned eye window.

`command()` is pure (unit-tested); `KioskWindow` runs and restarts one
browser process. Each window gets its own profile directory, which makes
it its own browser process: Chromium would otherwise hand a second
`--app` URL to the first process and ignore its position.
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Sequence
from pathlib import Path

from buddybot.eyes.placement import Window
from buddybot.runtime.backoff import Backoff

log = logging.getLogger("buddybot.eye-renderer.kiosk")

BROWSER_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

# Quiet, self-contained kiosk: no first-run UI, no crash bubbles, no
# background traffic (docs/design.md section 6: nothing talks to a network it
# was not told about).
KIOSK_FLAGS = (
    "--kiosk",
    "--no-first-run",
    "--no-default-browser-check",
    "--noerrdialogs",
    "--disable-infobars",
    "--disable-session-crashed-bubble",
    "--disable-translate",
    "--disable-features=Translate",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--password-store=basic",
    "--autoplay-policy=no-user-gesture-required",
)


def _die_with_parent() -> list[str]:
    """Prefix that makes the browser get SIGTERM when the renderer dies, even by
    SIGKILL, so a crashed renderer leaves no kiosk windows behind (util-linux
    `setpriv`, Linux). Not `preexec_fn`: unsafe in a process with threads."""
    setpriv = shutil.which("setpriv")
    return [setpriv, "--pdeathsig", "TERM", "--"] if setpriv else []


def find_browser(explicit: str = "") -> str | None:
    """The browser to use: an explicit path/name, else the first Chromium on PATH."""
    if explicit:
        return shutil.which(explicit) or (explicit if os.access(explicit, os.X_OK) else None)
    for name in BROWSER_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def page_url(base: str, eye: str) -> str:
    return f"{base.rstrip('/')}/eyes?eye={eye}"


def command(browser: str, url: str, window: Window, profile: Path,
            extra: Sequence[str] = ()) -> list[str]:
    """The browser's argv: an app window filling `window`'s display."""
    d = window.display
    return [
        browser,
        f"--app={url}",
        f"--window-position={d.x},{d.y}",
        f"--window-size={d.width},{d.height}",
        f"--user-data-dir={profile}",
        *KIOSK_FLAGS,
        *extra,
    ]


class KioskWindow:
    """One browser process, restarted with a backoff if it exits."""

    def __init__(self, argv: list[str], name: str) -> None:
        self.argv = argv
        self.name = name
        self.proc: subprocess.Popen[bytes] | None = None
        self.starts = 0
        self._next_start = 0.0
        # 1 s doubling to 30 s; a window that stayed open a minute starts over.
        self._backoff = Backoff(1.0, 30.0, stable_s=60.0)

    def start(self) -> None:
        self.starts += 1
        log.info("opening %s window: %s", self.name, " ".join(self.argv[:4]))
        # Same process group as the renderer: stopping the group (Ctrl-C, a
        # supervisor) stops the windows too.
        self.proc = subprocess.Popen(
            [*_die_with_parent(), *self.argv], stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        self._started_at = time.monotonic()

    def poll(self) -> None:
        """Restart a window that died (backoff 1 s doubling to 30 s)."""
        if self.proc is None or self.proc.poll() is None:
            return
        now = time.monotonic()
        if self._next_start == 0.0:
            delay = self._backoff.after_run(now - self._started_at)
            log.warning("%s window exited (status %s); reopening in %.0f s",
                        self.name, self.proc.returncode, delay)
            self._next_start = now + delay
        elif now >= self._next_start:
            self._next_start = 0.0
            self.start()

    def stop(self, timeout: float = 5.0) -> None:
        proc = self.proc
        if proc is None or proc.poll() is not None:
            return
        try:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
        except ProcessLookupError:
            pass
