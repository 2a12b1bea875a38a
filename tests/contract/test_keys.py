"""The key catalogue: one pattern per key, prefixes, matching, QoS as data."""

from __future__ import annotations

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m


def test_patterns_are_unique() -> None:
    patterns = [e.pattern for e in (*keys.TOPICS, *keys.SERVICES)]
    assert len(patterns) == len(set(patterns))


def test_prefix_and_absolute() -> None:
    assert keys.prefix("buddy") == "buddybot/buddy"
    assert keys.absolute("r2", "radar/presence") == "buddybot/r2/radar/presence"
    assert keys.absolute("r2", "/eyes/lids/") == "buddybot/r2/eyes/lids"
    assert keys.absolute("r2", "buddybot/other/eyes/lids") == "buddybot/other/eyes/lids"
    assert keys.split_absolute("buddybot/r2/camera/front/image") == ("r2", "camera/front/image")
    assert keys.split_absolute("other/thing") is None


@pytest.mark.parametrize(("key", "rel"), [
    ("buddybot/r2/camera/front/image", "camera/front/image"),
    ("buddybot/r2/eyes/*", "eyes/*"),
    ("buddybot/other/camera/front/image", "buddybot/other/camera/front/image"),
    ("elsewhere/r2/camera/front/image", "elsewhere/r2/camera/front/image"),
    ("camera/front/image", "camera/front/image"),
    ("buddybot/r2", "buddybot/r2"),
])
def test_relative_strips_only_this_robots_prefix(key: str, rel: str) -> None:
    assert keys.relative("r2", key) == rel


def test_relative_undoes_absolute() -> None:
    for entry in (*keys.TOPICS, *keys.SERVICES):
        assert keys.relative("r2", keys.absolute("r2", entry.pattern)) == entry.pattern


@pytest.mark.parametrize(("key", "entry"), [
    ("buddybot/r2/camera/front/image", keys.CAMERA_IMAGE),
    ("buddybot/buddy/audio/play_sound", keys.PLAY_SOUND),
    ("buddybot/buddy/camera/*/faces", keys.FACES),
    ("buddybot/buddy/eyes/unknown", None),
    ("buddybot/buddy", None),
    ("other/buddy/radar/presence", None),
    ("radar/presence", None),
])
def test_lookup_absolute(key: str, entry: keys.Topic | keys.Service | None) -> None:
    assert keys.lookup_absolute(key) is entry


@pytest.mark.parametrize("bad", ["", "a/b", "*", "**", "a b", "x$"])
def test_bad_robot_ids_are_refused(bad: str) -> None:
    with pytest.raises(ValueError, match="robot id"):
        keys.prefix(bad)


def test_lookup_and_params() -> None:
    assert keys.lookup("camera/front/image") is keys.CAMERA_IMAGE
    assert keys.lookup("camera/front/debug_image") is keys.DEBUG_IMAGE
    assert keys.lookup("radar/3/frames") is keys.RADAR_FRAMES
    assert keys.lookup("audio/play_sound") is keys.PLAY_SOUND
    assert keys.lookup("audio/play_sound/status") is keys.PLAY_SOUND_STATUS
    assert keys.lookup("eyes/unknown") is None
    assert keys.CAMERA_IMAGE.match("camera/side/image") == {"camera": "side"}
    assert keys.CAMERA_IMAGE.key(camera="front") == "camera/front/image"
    assert keys.CAMERA_IMAGE.wildcard() == "camera/*/image"
    with pytest.raises(ValueError, match="missing"):
        keys.CAMERA_IMAGE.key()
    with pytest.raises(ValueError, match="invalid"):
        keys.CAMERA_IMAGE.key(camera="a/b")


def test_qos_presets() -> None:
    """Nothing may block the router: every key drops under congestion, and every
    state key is latched (so a dropped state sample is recovered from the cache)."""
    for topic in keys.TOPICS:
        assert topic.qos.congestion == "drop", topic.pattern
    for topic in (keys.PRESENCE, keys.EXPRESSION, keys.LIDS, keys.DEVICE_FREE,
                  keys.PLAY_SOUND_STATUS):
        assert topic.qos is keys.STATE and topic.latched, topic.pattern
    for topic in keys.TOPICS:
        if topic.qos is keys.STATE:
            assert topic.latched, f"{topic.pattern}: a state key must be latched"


def test_payload_limits() -> None:
    """Only image keys accept large payloads; the router bound matches the largest."""
    from buddybot.runtime import node
    for topic in keys.TOPICS:
        big = topic.type is m.Image
        assert (topic.max_bytes == keys.IMAGE_MESSAGE_BYTES) == big, topic.pattern
        assert topic.max_bytes <= node.MAX_MESSAGE_BYTES
    for service in keys.SERVICES:
        assert service.max_bytes == keys.SMALL_MESSAGE_BYTES


def test_codec_for_encoding() -> None:
    assert keys.codec_for_encoding(keys.CAMERA_IMAGE.encoding) is keys.MSGPACK
    assert keys.codec_for_encoding("application/json;x") is keys.JSON
    assert keys.codec_for_encoding("text/plain") is None
