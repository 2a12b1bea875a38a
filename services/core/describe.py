"""Turn any BuddyBot sample into one readable line (for `echo` and zenoh-cli).

The catalogue decides the type from the key; a payload that does not
decode is shown as such rather than hidden, because a person probing the
robot wants to see bad traffic too.
"""

from __future__ import annotations

import json

import msgspec

from buddybot.core import keys
from buddybot.core import messages as m


def summarize(msg: m.Message) -> str:
    """JSON for control messages; a one-line summary for images.

    The image summary is built by a JSON encoder, never by string
    formatting: `frame_id` is free text from the wire, and a quote,
    backslash or newline in it must not turn `echo` output into invalid JSON.
    """
    if isinstance(msg, m.Image):
        return json.dumps({
            "type": "Image", "stamp_ns": msg.stamp_ns, "frame_id": msg.frame_id,
            "width": msg.width, "height": msg.height, "encoding": msg.encoding,
            "data": f"<{len(msg.data)} bytes>",
        })
    return msgspec.json.encode(msg).decode()


def describe(key: str, payload: bytes) -> str:
    """Decode a payload published on `key` (absolute) and summarize it."""
    parts = keys.split_absolute(key)
    entry = keys.lookup(parts[1]) if parts else None
    if isinstance(entry, keys.Topic):
        try:
            return summarize(entry.codec.decode(payload, entry.type))
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            return f"<malformed {entry.type.__name__}: {exc}; {len(payload)} bytes>"
    if isinstance(entry, keys.Service):
        for msg_type in (entry.request, entry.reply):
            try:
                return summarize(entry.codec.decode(payload, msg_type))
            except (msgspec.DecodeError, msgspec.ValidationError):
                continue
    try:
        return payload.decode("utf-8")
    except UnicodeDecodeError:
        return f"<{len(payload)} bytes>"
