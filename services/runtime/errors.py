"""The errors every part of BuddyBot raises, and the exit status each means.

A leaf module (it imports nothing of ours), so the runtime, the areas and
the command line can all raise and catch the same types without importing
each other. The policy is written once, in `exit_status`:

* 2, `UsageError` and its kinds: the command line or the configuration
  cannot be used. Restarting would fail the same way, so `buddybot up`
  and the systemd units (`RestartPreventExitStatus=2`) do not restart.
* 1, anything else that stops a command or service at run time: no
  router, a service call that failed, a device that vanished.
* 0, success (and a stop asked for with Ctrl-C or SIGTERM).
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2


class BuddyBotError(Exception):
    """Base of the errors below; its text is what the user sees."""


class UsageError(BuddyBotError):
    """Bad command-line usage: an unknown key, an invalid JSON message..."""


class ConfigError(UsageError):
    """A configuration that cannot be used; the message names file and key."""


class DuplicateNodeError(ConfigError):
    """Another process already runs a node of this name on this robot (exit 2:
    restarting would only collide again)."""


class ServeError(BuddyBotError):
    """A web or WebSocket server that cannot listen (its port is taken): exit 1,
    the port may be free later."""


class ServiceError(BuddyBotError):
    """A service call that failed: no answer, an error reply, or a bad reply."""


BUSY_PREFIX = "busy: "
"""How the error reply of a service whose request queue is full begins: the
caller may ask again shortly (a flood passes), unlike any other error."""


class CallError(ServiceError):
    """A failed call: `reason` is the text without the key (for messages that
    already say which service they called)."""

    def __init__(self, key: str, reason: str) -> None:
        super().__init__(f"{key}: {reason}")
        self.key = key
        self.reason = reason


class NoReplyError(CallError):
    """Nobody answered in time: the service is not (yet) declared, or is gone.
    Callers that wait for a starting service retry on this one only."""


class DeviceError(BuddyBotError):
    """A device that cannot be opened, or that answered wrongly (exit 1: it may
    work when plugged in again)."""


def exit_status(error: BaseException) -> int:
    """The process exit status for an error that ended a command or service."""
    if isinstance(error, UsageError):
        return EXIT_USAGE
    if isinstance(error, KeyboardInterrupt):
        return EXIT_OK
    return EXIT_FAILURE
