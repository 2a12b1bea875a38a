"""What the probing verbs (`buddybot echo|hz|pub|call|nodes`) share.

A probe opens a `Node` with `probe=True`: it talks only through the node's
handles, declares no liveliness token and publishes no diagnostics (a
probe is not a node of the robot). Keys may omit the `buddybot/<robot>/`
prefix and may contain wildcards; messages are decoded with the
catalogue's types.
"""

from __future__ import annotations

import time

import msgspec

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.errors import UsageError
from buddybot.core.node import Node
from buddybot.core.service import ServiceContext


def probe(ctx: ServiceContext) -> Node:
    """A probe node on the robot's router (waits for it; Ctrl-C aborts)."""
    return Node(ctx.name, robot=ctx.robot, connect=ctx.connect,
                zenoh_config_file=ctx.config.zenoh.config_file, stop_event=ctx.stop, probe=True)


def catalogue_entry(key: str) -> keys.Topic | keys.Service | None:
    """The catalogue entry an absolute key belongs to (None: not in the catalogue)."""
    parts = keys.split_absolute(key)
    return keys.lookup(parts[1]) if parts else None


def is_latched(key: str) -> bool:
    entry = catalogue_entry(key)
    return isinstance(entry, keys.Topic) and entry.latched


def deadline(seconds: float | None) -> float:
    """A monotonic end time; None or 0 means never."""
    return time.monotonic() + seconds if seconds else float("inf")


def parse_message(topic_or_type: type[m.Message], text: str) -> m.Message:
    """Validate user JSON against a message type; fills a missing `stamp_ns`.

    Raises UsageError naming the offending field.
    """
    try:
        raw = msgspec.json.decode(text or "{}")
    except msgspec.DecodeError as exc:
        raise UsageError(f"not valid JSON: {exc}") from None
    if not isinstance(raw, dict):
        raise UsageError(f"expected a JSON object for {topic_or_type.__name__}")
    if "stamp_ns" in topic_or_type.__struct_fields__ and "stamp_ns" not in raw:
        raw["stamp_ns"] = m.now_ns()
    try:
        return msgspec.convert(raw, topic_or_type)
    except msgspec.ValidationError as exc:
        text = str(exc).replace("$.", "").replace("`$`", "message")
        raise UsageError(f"invalid {topic_or_type.__name__}: {text}") from None
