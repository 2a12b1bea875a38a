"""The Foxglove SDK side of the bridge: channels, the WebSocket server, who watches.

No Zenoh here. Channels are made from `contract/channels.py` (the bag recorder
shows keys the same way) the first time a key is seen, and advertised to
every connected client at once.

Threads: `Channel.log` is the SDK's thread-safe entry point and never
blocks (each client has a bounded backlog: the oldest data message is
dropped when it is full), so Zenoh callbacks log straight into it. The
listener callbacks below run on the SDK's threads and only record the
change and set an event; the service's manager thread does the Zenoh
work they imply.
"""

from __future__ import annotations

import threading
from typing import Any

import foxglove
import msgspec
from foxglove.websocket import Capability, ChannelView, Client, ServerListener, WebSocketServer

from buddybot.contract import channels, keys
from buddybot.foxglove import logic
from buddybot.runtime.endpoints import serve_failure
from buddybot.runtime.errors import ServeError

SERVER_NAME = "buddybot"


class FoxgloveServer(ServerListener):
    """The channels of one bridge, its WebSocket server, and the server's listener."""

    def __init__(self, max_channels: int) -> None:
        self.context = foxglove.Context()
        self.max_channels = max_channels
        self._lock = threading.Lock()
        self._channels: dict[str, foxglove.Channel] = {}
        self._keys_by_id: dict[int, str] = {}
        self._demand = logic.Demand()
        self.changed = threading.Event()
        """Set when the set of watched channels changes (the manager waits on it)."""
        self.refused = 0
        """Keys not shown because `max_channels` channels exist."""
        self.server: WebSocketServer | None = None

    # -- channels --

    def channel(self, key: str, topic: keys.Topic) -> foxglove.Channel | None:
        """The channel of an absolute key, made (and advertised) the first time;
        None once `max_channels` exist."""
        found = self._channels.get(key)  # the common case: no lock (dict reads are atomic)
        if found is not None:
            return found
        spec = channels.channel(topic)
        return self._make(key, spec.schema_name, spec.schema)

    def annotations(self, faces_key: str) -> foxglove.Channel | None:
        """The `foxglove.ImageAnnotations` channel derived from a faces key."""
        key = logic.annotations_topic(faces_key)
        found = self._channels.get(key)
        if found is not None:
            return found
        return self._make(key, channels.ANNOTATIONS_SCHEMA, channels.ANNOTATIONS_SCHEMA_BYTES)

    def _make(self, key: str, schema_name: str, schema: bytes) -> foxglove.Channel | None:
        with self._lock:
            found = self._channels.get(key)
            if found is not None:
                return found
            if len(self._channels) >= self.max_channels:
                self.refused += 1
                return None
            made = foxglove.Channel(
                key, message_encoding=channels.MESSAGE_ENCODING, context=self.context,
                schema=foxglove.Schema(name=schema_name, encoding=channels.SCHEMA_ENCODING,
                                       data=schema))
            self._channels[key] = made
            self._keys_by_id[made.id()] = key
            return made

    def channel_count(self) -> int:
        return len(self._channels)

    def watched(self) -> set[str]:
        """Keys of the channels some client subscribes to now."""
        with self._lock:
            return {self._keys_by_id[i] for i in self._demand.wanted() if i in self._keys_by_id}

    # -- the SDK's ServerListener (called on its threads: record, signal, return) --

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        with self._lock:
            first = self._demand.subscribe(client.id, channel.id)
        if first:
            self.changed.set()

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        with self._lock:
            last = self._demand.unsubscribe(client.id, channel.id)
        if last:
            self.changed.set()

    # -- the server --

    def start(self, host: str = "127.0.0.1", port: int = 0) -> WebSocketServer:
        """Listen on host:port (ServeError, one line, when it cannot). The bridge
        puts it on loopback at a free port behind its gate (gate.py)."""
        try:
            self.server = foxglove.start_server(
                name=SERVER_NAME, host=host or "0.0.0.0", port=port, context=self.context,
                server_listener=self, capabilities=[Capability.Services],
                supported_encodings=[channels.MESSAGE_ENCODING])
        except RuntimeError as exc:  # the SDK's FoxgloveError: "Failed to bind port: ..."
            raise ServeError(serve_failure(host or "0.0.0.0", port, str(exc))) from None
        return self.server

    def add_services(self, services: list[foxglove.Service]) -> None:
        assert self.server is not None
        self.server.add_services(services)

    def stop(self) -> None:
        if self.server is not None:
            self.server.stop()
            self.server = None


def service_schema(name: str, request: dict[str, Any], response: dict[str, Any]
                   ) -> foxglove.ServiceSchema:
    """A Foxglove service schema with JSON requests and replies."""
    def message(schema: dict[str, Any]) -> foxglove.MessageSchema:
        return foxglove.MessageSchema(
            encoding=channels.MESSAGE_ENCODING,
            schema=foxglove.Schema(name=str(schema.get("title", name)),
                                   encoding=channels.SCHEMA_ENCODING,
                                   data=msgspec.json.encode(schema)))
    return foxglove.ServiceSchema(name, request=message(request), response=message(response))
