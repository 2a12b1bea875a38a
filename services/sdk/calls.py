"""One bounded service call, with the runtime's errors turned into the SDK's.

Written once for the speaker and the parameters: nobody answering is
`NoService` (naming the key, the wait and who should have answered), an error
reply is `SdkError` with the service's text.
"""

from __future__ import annotations

from typing import Any

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import CallError, NoReplyError
from buddybot.runtime.node import Node
from buddybot.sdk.errors import NoService, SdkError


def call(on: Node, service: keys.Service, request: m.Message, timeout: float, /, *,
         hint: str, **params: str) -> Any:
    """`on.call(...)`; NoService("nobody answered on <key> within <t> s (<hint>)")."""
    key = service.key(**params)
    try:
        return on.call_key(on.key(service, **params), service, request, timeout=timeout)
    except NoReplyError:
        raise NoService(f"nobody answered on {key} within {timeout:g} s ({hint})") from None
    except CallError as exc:
        raise SdkError(f"{key}: {exc.reason}") from None
