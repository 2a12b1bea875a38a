"""A minimal Foxglove WebSocket client for the tests: what the Foxglove app speaks.

Written from the protocol as the SDK's server speaks it (subprotocol
`foxglove.sdk.v1`): JSON text frames for control (`serverInfo`,
`advertise`, `subscribe`, ...), binary frames for data, little-endian:
`0x01 | subscription id u32 | log time u64 | payload` for a message,
`0x02/0x03 | service id u32 | call id u32 | encoding length u32 | encoding
| payload` for a service call and its response.
"""

from __future__ import annotations

import asyncio
import json
import struct
import time
from typing import Any

import websockets

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01
SERVICE_CALL_REQUEST = 0x02
SERVICE_CALL_RESPONSE = 0x03


class CallFailed(Exception):
    """The server answered a service call with `serviceCallFailure`."""


class FoxgloveClient:
    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.server_info: dict[str, Any] = {}
        self.channels: dict[str, dict[str, Any]] = {}
        """Advertised channels by topic."""
        self.services: dict[str, dict[str, Any]] = {}
        self.messages: list[tuple[int, int, bytes]] = []
        """(subscription id, log time, payload) received and not yet taken."""
        self.responses: dict[int, bytes | CallFailed] = {}

    @classmethod
    async def connect(cls, port: int, path: str = "") -> FoxgloveClient:
        """Connect to `ws://127.0.0.1:PORT` + `path` (e.g. "/?token=...")."""
        ws = await websockets.connect(f"ws://127.0.0.1:{port}{path}",
                                      subprotocols=[SUBPROTOCOL], max_size=None)
        client = cls(ws)
        await client.until(lambda: bool(client.server_info), 10, "serverInfo")
        return client

    async def close(self) -> None:
        await self.ws.close()

    async def _read(self, timeout: float) -> None:
        """Read one frame (or nothing within `timeout`) into the tables above."""
        try:
            frame = await asyncio.wait_for(self.ws.recv(), timeout)
        except TimeoutError:
            return
        if isinstance(frame, bytes):
            self._binary(frame)
            return
        msg = json.loads(frame)
        op = msg["op"]
        if op == "serverInfo":
            self.server_info = msg
        elif op == "advertise":
            self.channels.update({c["topic"]: c for c in msg["channels"]})
        elif op == "advertiseServices":
            self.services.update({s["name"]: s for s in msg["services"]})
        elif op == "serviceCallFailure":
            self.responses[msg["callId"]] = CallFailed(msg["message"])

    def _binary(self, frame: bytes) -> None:
        if frame[0] == MESSAGE_DATA:
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            self.messages.append((sub, log_time, frame[13:]))
        elif frame[0] == SERVICE_CALL_RESPONSE:
            _service, call, length = struct.unpack_from("<III", frame, 1)
            self.responses[call] = frame[13 + length:]

    async def until(self, done: Any, timeout: float, what: str) -> None:
        end = time.monotonic() + timeout
        while not done():
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no {what} within {timeout} s")
            await self._read(min(left, 0.2))

    async def channel(self, topic: str, timeout: float = 20.0) -> dict[str, Any]:
        await self.until(lambda: topic in self.channels, timeout, f"advertised {topic}")
        return self.channels[topic]

    async def subscribe(self, sub_id: int, topic: str) -> None:
        channel = await self.channel(topic)
        await self.ws.send(json.dumps({"op": "subscribe",
                                       "subscriptions": [{"id": sub_id,
                                                          "channelId": channel["id"]}]}))

    async def unsubscribe(self, sub_id: int) -> None:
        await self.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [sub_id]}))

    def take(self, sub_id: int) -> list[tuple[int, bytes]]:
        """(log time, payload) of the messages received on a subscription so far."""
        mine = [(t, p) for s, t, p in self.messages if s == sub_id]
        self.messages = [x for x in self.messages if x[0] != sub_id]
        return mine

    async def pump(self, seconds: float) -> None:
        """Keep reading for `seconds` (to count what arrives)."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            await self._read(min(left, 0.2))

    async def call(self, service: str, payload: bytes, call_id: int,
                   timeout: float = 20.0) -> bytes:
        """Call a service; its response payload, or CallFailed."""
        await self.until(lambda: service in self.services, timeout, f"service {service}")
        encoding = b"json"
        await self.ws.send(struct.pack("<BIII", SERVICE_CALL_REQUEST,
                                       self.services[service]["id"], call_id, len(encoding))
                           + encoding + payload)
        await self.until(lambda: call_id in self.responses, timeout, f"response to {service}")
        response = self.responses.pop(call_id)
        if isinstance(response, CallFailed):
            raise response
        return response
