"""Keys as MCAP/Foxglove channels: schemas, JSON both ways, images, annotations."""

from __future__ import annotations

import base64
import json

import cv2
import msgspec
import numpy as np
import pytest

from buddybot.contract import channels, keys
from buddybot.contract import messages as m
from tests.contract.test_messages import sample_messages


def _sample(msg_type: type) -> m.Message:
    return next(s for s in sample_messages() if type(s) is msg_type)


def _bgr_image(width: int = 64, height: int = 48) -> m.Image:
    pixels = np.zeros((height, width, 3), np.uint8)
    pixels[:, : width // 2] = (255, 0, 0)  # blue left half: survives JPEG
    return m.Image(stamp_ns=1_700_000_000_123_456_789, frame_id="cam0", width=width,
                   height=height, encoding="bgr8", data=pixels.tobytes())


@pytest.mark.parametrize("topic", [t for t in keys.TOPICS if not channels.is_image(t)],
                         ids=lambda t: t.pattern)
def test_every_non_image_key_round_trips_byte_for_byte(topic: keys.Topic) -> None:
    payload = topic.codec.encode(_sample(topic.type))
    data = channels.to_json(topic, payload)
    json.loads(data)  # plain JSON a viewer can read
    assert channels.from_json(topic, data) == payload


@pytest.mark.parametrize("topic", keys.TOPICS, ids=lambda t: t.pattern)
def test_every_schema_is_self_contained_json_schema(topic: keys.Topic) -> None:
    ch = channels.channel(topic)
    schema = json.loads(ch.schema)
    assert "$ref" not in ch.schema.decode() and "$defs" not in schema
    assert schema["type"] == "object"
    if ch.image:
        assert ch.schema_name == "foxglove.CompressedImage"
    else:
        assert ch.schema_name == f"buddybot.{topic.type.__name__}"
        fields = {f.encode_name for f in msgspec.structs.fields(topic.type)}
        assert set(schema["properties"]) == fields


def test_enum_names_survive_inlining() -> None:
    schema = json.loads(channels.channel(keys.EXPRESSION).schema)
    assert schema["properties"]["action"]["x-enum-names"][1] == "EYE_SLEEP"


def test_a_raw_frame_becomes_a_jpeg_compressed_image_and_comes_back_as_jpeg() -> None:
    image = _bgr_image()
    data = channels.to_json(keys.CAMERA_IMAGE, keys.CAMERA_IMAGE.codec.encode(image))
    value = json.loads(data)
    assert value["format"] == "jpeg" and value["frame_id"] == "cam0"
    assert value["timestamp"] == {"sec": 1_700_000_000, "nsec": 123_456_789}
    decoded = cv2.imdecode(np.frombuffer(base64.b64decode(value["data"]), np.uint8), 1)
    assert decoded.shape == (48, 64, 3)
    assert decoded[10, 5, 0] > 200 and decoded[10, 60, 0] < 50
    back = keys.CAMERA_IMAGE.codec.decode(channels.from_json(keys.CAMERA_IMAGE, data), m.Image)
    assert (back.encoding, back.width, back.height, back.stamp_ns) == ("jpeg", 64, 48,
                                                                        image.stamp_ns)


def test_a_jpeg_frame_passes_through_untouched() -> None:
    jpeg = channels.jpeg_bytes(_bgr_image(33, 17))
    image = m.Image(stamp_ns=5, frame_id="c", width=33, height=17, encoding="jpeg", data=jpeg)
    data = channels.to_json(keys.DEBUG_IMAGE, keys.DEBUG_IMAGE.codec.encode(image))
    assert base64.b64decode(json.loads(data)["data"]) == jpeg


@pytest.mark.parametrize("payload", [b"", b"\x00garbage", b'{"stamp_ns": -1}'])
def test_bad_payloads_are_a_channel_error(payload: bytes) -> None:
    for topic in (keys.PRESENCE, keys.CAMERA_IMAGE):
        with pytest.raises(channels.ChannelError):
            channels.to_json(topic, payload)
        with pytest.raises(channels.ChannelError):
            channels.from_json(topic, payload)


@pytest.mark.parametrize("value", [
    {"timestamp": {"sec": 1, "nsec": 0}, "data": "!!notbase64", "format": "jpeg"},
    {"timestamp": {"sec": 1, "nsec": 0}, "data": base64.b64encode(b"\xff\xd8\xff").decode(),
     "format": "jpeg"},
    {"timestamp": {"sec": 1, "nsec": 0}, "data": "", "format": "png"},
    {"data": ""},
    [1, 2],
])
def test_a_bad_compressed_image_is_refused(value: object) -> None:
    with pytest.raises(channels.ChannelError):
        channels.from_json(keys.CAMERA_IMAGE, json.dumps(value).encode())


def test_a_bgr8_frame_of_the_wrong_size_is_refused() -> None:
    image = m.Image(stamp_ns=1, frame_id="c", width=10, height=10, encoding="bgr8", data=b"x")
    with pytest.raises(channels.ChannelError, match="300 bytes"):
        channels.jpeg_bytes(image)


def test_annotations_draw_each_face_and_label_the_followed_one() -> None:
    det = m.FaceDetections(
        stamp_ns=2_000_000_001, frame_id="cam0", width=640, height=480,
        faces=[m.FaceBox(x0=10, y0=20, x1=110, y1=140, score=0.9, followed=True,
                         keypoints=[m.PixelPoint(x=40, y=60)] * 6),
               m.FaceBox(x0=300, y0=50, x1=350, y1=110, score=0.7)],
        distance_m=0.62,
        cues=[m.DistanceCue(name="eyes", distance_m=0.6, weight=0.3, status="used"),
              m.DistanceCue(name="iris", distance_m=0.63, weight=0.7, status="used")])
    ann = channels.annotations(det)
    boxes = [p for p in ann["points"] if p["type"] == 2]
    assert [b["points"][0] for b in boxes] == [{"x": 10, "y": 20}, {"x": 300, "y": 50}]
    assert boxes[0]["outline_color"] != boxes[1]["outline_color"]
    assert ann["texts"][0]["text"] == "0.90  0.62 m (iris)"
    assert ann["texts"][1]["text"] == "0.70"
    assert ann["points"][0]["timestamp"] == {"sec": 2, "nsec": 1}
    assert channels.annotations(m.FaceDetections(
        stamp_ns=1, frame_id="c", width=1, height=1)) == {"circles": [], "points": [],
                                                          "texts": []}
