"""The bridge's pure rules and its SDK side, without processes or a router."""

from __future__ import annotations

import json
import os
import socket

import foxglove
import psutil
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.foxglove import logic
from buddybot.foxglove.server import FoxgloveServer
from buddybot.foxglove.service import urls
from buddybot.foxglove.settings import FoxgloveSettings
from buddybot.runtime.endpoints import serve_failure
from buddybot.runtime.errors import ServeError


def test_a_15_fps_camera_limited_to_10_gives_10_per_second() -> None:
    limiter = logic.RateLimiter(10.0)
    sent = sum(limiter.allow(i / 15.0) for i in range(15 * 4))  # 4 s of frames
    assert sent == 40
    assert limiter.skipped == 20


def test_a_slow_source_is_never_limited_and_a_pause_grants_no_burst() -> None:
    limiter = logic.RateLimiter(10.0)
    assert all(limiter.allow(i * 0.5) for i in range(10))  # 2 fps: all pass
    # After a long pause, frames at 100 fps: only one per 0.1 s gets through.
    sent = sum(limiter.allow(100.0 + i / 100.0) for i in range(100))
    assert sent == 10


def test_a_rate_must_be_positive() -> None:
    with pytest.raises(ValueError):
        logic.RateLimiter(0.0)
    with pytest.raises(ValueError):
        logic.RateLimiter(1.0).set_rate(-1.0)


def test_a_new_rate_applies_from_the_next_slot() -> None:
    limiter = logic.RateLimiter(10.0)
    assert sum(limiter.allow(i / 100.0) for i in range(100)) == 10  # 1 s at 100 fps
    limiter.set_rate(2.0)
    assert sum(limiter.allow(1.0 + i / 100.0) for i in range(200)) in (4, 5)  # 2 s


def test_demand_follows_the_first_and_last_client_of_a_channel() -> None:
    demand = logic.Demand()
    assert demand.subscribe(client=1, channel=7) is True
    assert demand.subscribe(client=2, channel=7) is False
    assert demand.wanted() == {7}
    assert demand.unsubscribe(client=1, channel=7) is False
    assert demand.unsubscribe(client=3, channel=7) is False  # never subscribed
    assert demand.unsubscribe(client=2, channel=7) is True
    assert demand.wanted() == set()
    assert demand.unsubscribe(client=2, channel=7) is False  # twice: nothing left


def test_plan_opens_the_wanted_and_closes_the_rest() -> None:
    assert logic.plan({"a", "b"}, {"b", "c"}) == ({"a"}, {"c"})


def test_images_are_found_from_what_nodes_say_they_publish() -> None:
    infos = [
        m.NodeInfo(node="camera", instance="1", publishers=["camera/front/image"]),
        m.NodeInfo(node="face-detector", instance="2",
                   publishers=["camera/front/debug_image", "camera/front/faces"]),
        m.NodeInfo(node="probe", instance="3",
                   publishers=["camera/*/image", "radar/presence", "not/a/key"]),
    ]
    assert logic.declared_images(infos) == {"camera/front/image", "camera/front/debug_image"}


def test_the_topics_split_into_images_and_the_rest() -> None:
    assert set(logic.image_topics()) == {keys.CAMERA_IMAGE, keys.DEBUG_IMAGE}
    assert set(logic.image_topics()) | set(logic.streamed_topics()) == set(keys.TOPICS)
    assert logic.topic_of("camera/side/faces") is keys.FACES
    assert logic.topic_of("audio/play_sound") is None  # a service, not a topic
    assert logic.annotations_topic("buddybot/buddy/camera/front/faces") == (
        "buddybot/buddy/camera/front/faces/annotations")


def test_a_service_request_needs_no_stamp() -> None:
    schema = logic.request_schema(m.ScreenExpression)
    assert "stamp_ns" not in schema.get("required", [])
    assert "action" in schema["required"]
    assert "x-enum-names" in json.dumps(schema)  # the app can show EYE_HAPPY, not 3


def test_urls_name_a_reachable_host_and_open_the_app_on_it() -> None:
    ws, app = urls("0.0.0.0", 8765)
    assert ws == "ws://127.0.0.1:8765"
    assert app == ("https://app.foxglove.dev/?ds=foxglove-websocket"
                   "&ds.url=ws%3A%2F%2F127.0.0.1%3A8765")
    assert urls("buddy.local", 9000)[0] == "ws://buddy.local:9000"


def test_defaults() -> None:
    s = FoxgloveSettings()
    assert (s.host, s.port, s.images, s.max_image_fps) == ("127.0.0.1", 8765, True, 10.0)


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
