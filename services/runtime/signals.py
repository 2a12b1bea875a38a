"""SIGINT/SIGTERM as a stop event, without ever deadlocking the process."""

from __future__ import annotations

import logging
import os
import signal
import threading

log = logging.getLogger("buddybot.node")


def install_signal_handlers(stop: threading.Event) -> None:
    """SIGINT/SIGTERM set `stop`, so the main loop can shut down cleanly.

    The Python-level handler does nothing: a handler runs in the main thread
    between two bytecodes, and one that took a lock (`Event.set`, logging) could
    interrupt that same thread while it held the lock and deadlock it. This
    happened: a service that got SIGTERM while its main thread sat in
    `stop.wait()` hung forever. Instead the C-level handler writes the signal
    number to a pipe (`signal.set_wakeup_fd`) and a watcher thread sets `stop`.
    Call from the main thread.
    """
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)
    signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    wanted = {int(signal.SIGINT), int(signal.SIGTERM)}

    def watch() -> None:
        while True:
            data = os.read(read_fd, 64)
            for signum in data:
                if signum in wanted:
                    log.info("received %s, stopping", signal.Signals(signum).name)
                    stop.set()

    threading.Thread(target=watch, name="signals", daemon=True).start()

    def handler(_signum: int, _frame: object) -> None:
        """Nothing here (see above): the wakeup fd carries the signal."""

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
