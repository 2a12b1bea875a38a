"""One bounded service call, with the runtime's errors turned into the SDK's.

Written once for the speaker, the parameters and the leases: nobody answering
is `NoService` (naming the key, the wait and who should have answered), an
error reply is `SdkError` with the service's text. `sdk_errors` is the
translation alone, for calls made by the runtime (`buddybot.runtime.leasing`).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import CallError, NoReplyError
from buddybot.runtime.node import Node
from buddybot.sdk.errors import NoService, SdkError


def call(on: Node, service: keys.Service, request: m.Message, timeout: float, /, *,
         hint: str, **params: str) -> Any:
    """`on.call(...)`; NoService("nobody answered on <key> within <t> s (<hint>)")."""
    with sdk_errors(service, timeout, hint=hint, **params):
        return on.call_key(on.key(service, **params), service, request, timeout=timeout)


@contextmanager
def sdk_errors(service: keys.Service, timeout: float, /, *, hint: str,
               **params: str) -> Iterator[None]:
    """The runtime's call errors on `service`, raised in the block, as the SDK's:
    NoService for no answer within `timeout`, SdkError for a bad reply."""
    key = service.key(**params)
    try:
        yield
    except NoReplyError:
        raise NoService(f"nobody answered on {key} within {timeout:g} s ({hint})") from None
    except CallError as exc:
        raise SdkError(f"{key}: {exc.reason}") from None
