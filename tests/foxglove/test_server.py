"""The Foxglove SDK side of the bridge (services/foxglove/server.py), without Zenoh:
channels, the WebSocket server and its start-up failures in one line."""

from __future__ import annotations

import json
import os
import socket

import foxglove
import psutil
import pytest

from buddybot.contract import keys
from buddybot.foxglove.server import FoxgloveServer
from buddybot.runtime.endpoints import serve_failure
from buddybot.runtime.errors import ServeError


def test_channels_are_made_once_with_their_schema_and_bounded() -> None:
    fox = FoxgloveServer(max_channels=3)
    presence = fox.channel("buddybot/buddy/radar/presence", keys.PRESENCE)
    assert presence is not None
    assert fox.channel("buddybot/buddy/radar/presence", keys.PRESENCE) is presence
    assert presence.schema_name() == "buddybot.PresenceDetection"
    assert presence.message_encoding == "json"
    schema = presence.schema()
    assert schema is not None and schema.encoding == "jsonschema"
    assert json.loads(schema.data)["title"] == "PresenceDetection"
    image = fox.channel("buddybot/buddy/camera/front/image", keys.CAMERA_IMAGE)
    assert image is not None and image.schema_name() == "foxglove.CompressedImage"
    boxes = fox.annotations("buddybot/buddy/camera/front/faces")
    assert boxes is not None and boxes.schema_name() == "foxglove.ImageAnnotations"
    assert boxes.topic() == "buddybot/buddy/camera/front/faces/annotations"
    # A fourth key (anyone can invent `radar/<x>/frames`) is refused and counted.
    assert fox.channel("buddybot/buddy/radar/x/frames", keys.RADAR_FRAMES) is None
    assert (fox.channel_count(), fox.refused) == (3, 1)


def test_a_busy_port_is_one_clear_error() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ServeError) as err:
            FoxgloveServer(8).start("127.0.0.1", port)
    text = str(err.value)
    # The holder is named (this test's own process) and the way out given.
    assert text == (f"cannot serve on 127.0.0.1:{port}: the port is taken by "
                    f"{psutil.Process().name()}, pid {os.getpid()} (Address already in use); "
                    "stop it or give --port another port")


def test_other_failures_are_one_line_too() -> None:
    assert serve_failure("10.1.2.3", 9, "FoxgloveError: Failed to bind port: Cannot assign "
                         "requested address (os error 99)") == (
        "cannot serve on 10.1.2.3:9: Cannot assign requested address")


def test_the_server_serves_on_a_free_port_and_stops() -> None:
    fox = FoxgloveServer(8)
    server = fox.start("127.0.0.1", 0)
    try:
        assert server.port > 0
        assert isinstance(server, foxglove.websocket.WebSocketServer)
    finally:
        fox.stop()
