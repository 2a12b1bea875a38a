"""The bridge's pure rules (services/foxglove/logic.py): channels, demand, rates."""

from __future__ import annotations

import json

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.foxglove import logic


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
