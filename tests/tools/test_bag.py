"""The recording format without processes: writing, checked reading, timing."""

from __future__ import annotations

import json
import random
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.writer import Writer

from buddybot.contract import channels, keys
from buddybot.contract import messages as m
from buddybot.tools import bag
from tests.contract.test_messages import sample_messages

PARAMS = {"camera": "front", "device": "0", "node": "radar-presence"}


def concrete_key(topic: keys.Topic, robot: str = "buddy") -> str:
    return keys.absolute(robot, topic.key(**{p: PARAMS[p] for p in topic.params}))


def samples() -> dict[str, tuple[keys.Topic, bytes]]:
    """One payload of every topic of the catalogue, on its concrete key."""
    by_type = {type(x): x for x in sample_messages()}
    return {concrete_key(t): (t, t.codec.encode(by_type[t.type])) for t in keys.TOPICS}


def write_recording(path: Path, items: list[tuple[str, bytes, int]], robot: str = "buddy"
                    ) -> bag.BagWriter:
    writer = bag.BagWriter(path, robot=robot)
    for key, payload, arrival in items:
        assert writer.write(key, payload, arrival)
    writer.close()
    return writer


@pytest.fixture
def every_topic(tmp_path: Path) -> tuple[Path, dict[str, tuple[keys.Topic, bytes]], int]:
    base = time.time_ns()
    found = samples()
    items = [(key, payload, base + i * 10_000_000) for i, (key, (_t, payload))
             in enumerate(found.items())]
    path = tmp_path / "all.mcap"
    write_recording(path, items)
    return path, found, base


def test_every_topic_round_trips_byte_for_byte(every_topic: tuple[Path, dict, int]) -> None:
    path, found, _ = every_topic
    played = {p.key: p for p in bag.open_recording(path).messages()}
    assert set(played) == set(found)
    for key, (topic, payload) in found.items():
        if channels.is_image(topic):
            image = topic.codec.decode(played[key].payload, m.Image)
            assert image.encoding == "jpeg" and (image.width, image.height) == (2, 1)
            pixels = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
            assert pixels is not None and pixels.shape == (1, 2, 3)
        else:
            assert played[key].payload == payload, key


def test_times_metadata_and_the_derived_annotations(every_topic: tuple[Path, dict, int]
                                                    ) -> None:
    path, found, base = every_topic
    from mcap.reader import make_reader

    with path.open("rb") as stream:
        reader = make_reader(stream)
        meta = {r.name: r.metadata for r in reader.iter_metadata()}
        seen = {}
        for schema, channel, message in reader.iter_messages():
            seen[channel.topic] = (schema, channel, message)
    assert meta["buddybot"]["robot"] == "buddy" and meta["buddybot"]["version"]
    presence_key = concrete_key(keys.PRESENCE)
    _schema, _channel, message = seen[presence_key]
    stamp = json.loads(message.data)["stamp_ns"]
    assert message.publish_time == stamp and message.log_time >= base
    annotations = bag.annotations_key(concrete_key(keys.FACES))
    schema, channel, message = seen[annotations]
    assert schema.name == channels.ANNOTATIONS_SCHEMA and bag.DERIVED in channel.metadata
    assert json.loads(message.data)["points"]  # the face's box
    info = bag.read_info(path)
    skipped = {c.key: c.skipped for c in info.channels}
    assert skipped[annotations] == bag.DERIVED
    assert all(not s for k, s in skipped.items() if k != annotations)
    assert info.messages == len(found) + 1
    assert annotations not in {p.key for p in bag.open_recording(path).messages()}


def test_a_truncated_file_is_refused(every_topic: tuple[Path, dict, int],
                                     tmp_path: Path) -> None:
    path, _, _ = every_topic
    data = path.read_bytes()
    for cut in (0, 7, 100, len(data) // 2, len(data) - 1):
        broken = tmp_path / f"cut{cut}.mcap"
        broken.write_bytes(data[:cut])
        with pytest.raises(bag.BagError) as caught:
            bag.open_recording(broken)
        assert "truncated" in str(caught.value) or "empty" in str(caught.value)
        assert "\n" not in str(caught.value)


def test_every_flipped_byte_is_refused(every_topic: tuple[Path, dict, int],
                                       tmp_path: Path) -> None:
    """Data section (chunk CRC, data CRC) and summary (its CRC, checked here)."""
    path, _, _ = every_topic
    data = path.read_bytes()
    rng = random.Random(7)
    broken = tmp_path / "flipped.mcap"
    for position in rng.sample(range(len(data)), 150):
        flipped = bytearray(data)
        flipped[position] ^= 0x55
        broken.write_bytes(bytes(flipped))
        with pytest.raises(bag.BagError):
            bag.open_recording(broken)
    broken.write_bytes(data)
    assert len(list(bag.open_recording(broken).messages())) == len(samples())


def test_not_mcap_and_missing_files(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_text("hello world, not a recording at all")
    with pytest.raises(bag.BagError, match="not an MCAP file"):
        bag.read_info(tmp_path / "x.mcap")
    with pytest.raises(bag.BagError, match="cannot read"):
        bag.read_info(tmp_path / "none.mcap")


def test_unknown_channels_are_listed_and_skipped(tmp_path: Path) -> None:
    path = tmp_path / "foreign.mcap"
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("x", "jsonschema", b"{}")
        foreign = writer.register_channel("other/thing", "json", schema)
        ours = writer.register_channel(concrete_key(keys.DEVICE_FREE), "json",
                                       writer.register_schema("buddybot.Bool", "jsonschema",
                                                              b"{}"))
        payload = keys.DEVICE_FREE.codec.encode(m.Bool(stamp_ns=m.now_ns(), data=True))
        writer.add_message(foreign, log_time=1, data=b"{}", publish_time=1)
        writer.add_message(ours, log_time=2, data=payload, publish_time=2)
        writer.finish()
    recording = bag.open_recording(path)
    assert [c.key for c in recording.unknown] == ["other/thing"]
    assert [(p.key, p.payload) for p in recording.messages()] == [
        (concrete_key(keys.DEVICE_FREE), payload)]


def test_a_malformed_message_in_a_file_is_refused_before_playing(tmp_path: Path) -> None:
    path = tmp_path / "bad.mcap"
    ch = channels.channel(keys.PUPIL)
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        cid = writer.register_channel(concrete_key(keys.PUPIL), "json",
                                      writer.register_schema(ch.schema_name, "jsonschema",
                                                             ch.schema))
        writer.add_message(cid, log_time=1, data=b'{"stamp_ns":1,"dilation_percentage":500}',
                           publish_time=1)
        writer.finish()
    with pytest.raises(bag.BagError, match=r"not a valid buddybot\.PupilControl"):
        bag.open_recording(path)


def test_the_writer_refuses_bad_payloads_and_foreign_keys(tmp_path: Path) -> None:
    writer = bag.BagWriter(tmp_path / "w.mcap", robot="buddy")
    with pytest.raises(channels.ChannelError):
        writer.write(concrete_key(keys.PUPIL), b'{"nope": 1}', 1)
    assert not writer.write("buddybot/buddy/no/such/key", b"{}", 1)
    assert not writer.write("elsewhere/key", b"{}", 1)
    writer.close()
    assert bag.read_info(tmp_path / "w.mcap").messages == 0


def test_schedule_and_keys() -> None:
    assert bag.schedule_s(3_000_000_000, 1_000_000_000, 1.0) == 2.0
    assert bag.schedule_s(3_000_000_000, 1_000_000_000, 2.0) == 1.0
    assert bag.schedule_s(0, 1_000_000_000, 1.0) == 0.0
    with pytest.raises(ValueError):
        bag.schedule_s(1, 0, 0)
    key = "buddybot/buddy/camera/front/faces"
    assert bag.key_matches("buddybot/*/camera/front/faces", key)
    assert bag.key_matches("buddybot/buddy/camera/**", key)
    assert bag.key_matches("buddybot/**", key)
    assert bag.key_matches("buddybot/buddy/camera/fr*/faces", key)
    assert not bag.key_matches("buddybot/buddy/camera/*", key)
    assert not bag.key_matches("buddybot/other/**", key)
    assert bag.with_robot(key, "b2") == "buddybot/b2/camera/front/faces"
    assert bag.with_robot(key, None) == key
    assert bag.topic_of(key) is keys.FACES
    assert bag.topic_of("buddybot/buddy/audio/play_sound") is None  # a service
    assert bag.topic_of("buddybot/buddy/camera/*/faces") is None
