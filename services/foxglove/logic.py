"""The bridge's pure rules: which keys become channels, who watches what, how often.

No Zenoh, no SDK, no threads: the service (`service.py`) calls these with
the clock and what it saw, and tests call them the same way.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from buddybot.contract import channels, keys
from buddybot.contract import messages as m

ANNOTATIONS_SUFFIX = "/annotations"
"""Topic of the boxes drawn over a camera's image: `<faces key>/annotations`."""


def topic_of(relative_key: str) -> keys.Topic | None:
    """The catalogue topic a concrete relative key belongs to (None: not a topic)."""
    entry = keys.lookup(relative_key)
    return entry if isinstance(entry, keys.Topic) else None


def image_topics() -> tuple[keys.Topic, ...]:
    """Catalogue topics carrying images (sent only while a client watches them)."""
    return tuple(t for t in keys.TOPICS if channels.is_image(t))


def streamed_topics() -> tuple[keys.Topic, ...]:
    """Catalogue topics bridged all the time (everything but images)."""
    return tuple(t for t in keys.TOPICS if not channels.is_image(t))


def annotations_topic(faces_key: str) -> str:
    return faces_key + ANNOTATIONS_SUFFIX


def declared_images(infos: Iterable[m.NodeInfo]) -> set[str]:
    """Relative image keys some node publishes, from the nodes' own reports.

    Images are found this way, not by listening: subscribing to every image
    key would pull every frame over the bus (and make the face detector draw
    its debug image, which it does only while watched) just to learn a name.
    """
    found: set[str] = set()
    for info in infos:
        for key in info.publishers:
            if "*" in key:
                continue
            topic = topic_of(key)
            if topic is not None and channels.is_image(topic):
                found.add(key)
    return found


class RateLimiter:
    """At most `max_per_s` events per second, spread evenly.

    Slots are scheduled from the previous slot, not from the last event, so a
    15 fps camera limited to 10 fps gives 10 fps (a limit measured from the
    last frame sent would give 7.5: every other frame). After a pause the
    schedule restarts from now instead of granting a burst.
    """

    def __init__(self, max_per_s: float) -> None:
        self.period = 0.0
        self.set_rate(max_per_s)
        self._next: float | None = None
        self.skipped = 0

    def set_rate(self, max_per_s: float) -> None:
        if max_per_s <= 0:
            raise ValueError("max_per_s must be positive")
        self.period = 1.0 / max_per_s

    def allow(self, now: float) -> bool:
        if self._next is not None and now < self._next:
            self.skipped += 1
            return False
        if self._next is None or now - self._next > self.period:
            self._next = now + self.period
        else:
            self._next += self.period
        return True


@dataclass
class Demand:
    """Which Foxglove clients subscribe to which channel (by channel id).

    The SDK reports each client's subscribe and unsubscribe (a disconnect
    unsubscribes everything); a channel is wanted while one client is left.
    """

    _clients: dict[int, set[int]] = field(default_factory=dict)

    def subscribe(self, client: int, channel: int) -> bool:
        """Record a subscription; True when it is the channel's first."""
        clients = self._clients.setdefault(channel, set())
        first = not clients
        clients.add(client)
        return first

    def unsubscribe(self, client: int, channel: int) -> bool:
        """Forget a subscription; True when it was the channel's last."""
        clients = self._clients.get(channel)
        if not clients or client not in clients:
            return False
        clients.discard(client)
        if clients:
            return False
        del self._clients[channel]
        return True

    def wanted(self) -> set[int]:
        return set(self._clients)


def plan(wanted: set[str], open_keys: set[str]) -> tuple[set[str], set[str]]:
    """(keys to subscribe to, keys to stop) so the open set becomes `wanted`."""
    return wanted - open_keys, open_keys - wanted


# --- the Foxglove services ----------------------------------------------------------

EXPRESSION_SERVICE = "eyes/expression"
RELEASE_SERVICE = "eyes/release"
PLAY_SOUND_SERVICE = "audio/play_sound"


def request_schema(msg_type: type[m.Message]) -> dict[str, Any]:
    """The JSON Schema of a service request: the message's, with `stamp_ns` optional
    (the bridge stamps it) so the app's service panel asks only for what matters."""
    schema = channels.message_schema(msg_type)
    if "required" in schema:
        schema["required"] = [f for f in schema["required"] if f != "stamp_ns"]
    return schema
