"""What a child process needs from the supervisor that started it (`buddybot up`).

`up` puts its pid in each child's environment (`SUPERVISOR_ENV`); the child,
first thing, asks the kernel for SIGTERM when `up` dies. This lives with the
runtime, not with `up`, because every service runs it and a service must not
load the supervisor to start.
"""

from __future__ import annotations

import ctypes
import logging
import os
import signal
import sys
from collections.abc import MutableMapping

log = logging.getLogger("buddybot.service")

SUPERVISOR_ENV = "BUDDYBOT_SUPERVISOR_PID"
"""Set in each child's environment to the pid of the `up` that started it."""
_PR_SET_PDEATHSIG = 1


def die_with_supervisor(env: MutableMapping[str, str]) -> bool:
    """In a child of `up`, first thing: have the kernel send SIGTERM when `up` dies.

    The child sets this itself rather than through `preexec_fn`, which runs
    Python between fork and exec in a multi-threaded parent (output pumps,
    Zenoh) and can deadlock there. The price is a short window, from exec to
    this call, in which the parent could die unnoticed; comparing the parent's
    pid with the one `up` put in the environment closes it. PR_SET_PDEATHSIG
    fires when the *thread* that forked us ends, so `up` starts every child
    from its main thread, which lives as long as `up` does.

    SIGTERM rather than SIGKILL: the child leaves the way Ctrl-C makes it
    leave (the eye renderer closes its kiosk browsers, the player its device),
    which takes about two seconds for the whole robot.

    Returns False when the supervisor is already gone (the caller exits).
    Without the variable (not started by `up`) nothing is done.
    """
    raw = env.pop(SUPERVISOR_ENV, "")  # not inherited by our own children
    if not raw.isdigit():
        return True
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) != 0:
            log.warning("prctl(PR_SET_PDEATHSIG) failed: %s", os.strerror(ctypes.get_errno()))
    return os.getppid() == int(raw)
