"""The errors a program using `buddybot.sdk` catches: one base, four kinds.

Every SDK call is bounded by a timeout, so a program never hangs on a
missing router or service: it gets one of these, whose text says what was
asked, of whom, and for how long.
"""

from __future__ import annotations

from buddybot.runtime.errors import BuddyBotError


class SdkError(BuddyBotError):
    """Base of every error the SDK raises on purpose."""


class NoRouter(SdkError, ConnectionError):
    """No Zenoh router answered on the endpoints within the connect timeout."""

    def __init__(self, text: str, endpoints: list[str]) -> None:
        super().__init__(text)
        self.endpoints = endpoints


class TimedOut(SdkError, TimeoutError):
    """What was waited for did not happen in time; the text names it."""


class Refused(SdkError):
    """A service answered and said no; `reason` is its own words."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class NoService(SdkError):
    """No process answered (or published) where the service should be."""
