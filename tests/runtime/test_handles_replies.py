"""`service_reply`: which reply to a call counts, and what nobody answering is."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import CallError, NoReplyError
from buddybot.runtime.handles import RawReply, error_payload, service_reply

KEY = "buddybot/buddy/audio/play_file"


def reply(ok: bool, payload: bytes) -> RawReply:
    return RawReply(ok=ok, payload=payload, encoding="application/json",
                    key=KEY if ok else None, replier="a5404782" if ok else None)


def test_the_first_good_reply_is_decoded_with_its_replier() -> None:
    good = msgspec.json.encode(m.TriggerReply(success=True, message="ok"))
    got = service_reply(iter([reply(True, good)]), KEY, keys.PLAY_FILE, 5.0)
    assert got.value == m.TriggerReply(success=True, message="ok")
    assert got.replier == "a5404782"


def test_an_error_reply_of_the_service_is_a_call_error_with_its_text() -> None:
    with pytest.raises(CallError, match="no such file") as caught:
        service_reply(iter([reply(False, error_payload("no such file"))]), KEY,
                      keys.PLAY_FILE, 5.0)
    assert not isinstance(caught.value, NoReplyError)


def test_zenohs_timeout_reply_is_no_reply() -> None:
    """A router answers "Timeout" for a queryable that did not answer in time (a
    player killed a moment before): nobody answered, as with no reply at all,
    so a caller that retries on no reply retries on this too."""
    with pytest.raises(NoReplyError, match="no reply within 5 s"):
        service_reply(iter([reply(False, b"Timeout")]), KEY, keys.PLAY_FILE, 5.0)
    with pytest.raises(NoReplyError):
        service_reply(iter([]), KEY, keys.PLAY_FILE, 5.0)


def test_a_good_reply_after_a_timeout_reply_still_counts() -> None:
    good = msgspec.json.encode(m.TriggerReply(success=True, message="ok"))
    got = service_reply(iter([reply(False, b"Timeout"), reply(True, good)]), KEY,
                        keys.PLAY_FILE, 5.0)
    assert got.value.success
