"""How a catalogue key becomes a channel of an MCAP file or a Foxglove server, and back.

Recording (`buddybot bag`) and the Foxglove bridge show the same keys the
same way, so both take their channels from here:

* every key is a channel with message encoding `json` and a `jsonschema`
  schema generated from its msgspec type (refs inlined: viewers handle one
  self-contained schema best), named `buddybot.<Type>`;
* camera images become `foxglove.CompressedImage` (JPEG, base64 in JSON),
  the schema Foxglove's Image panel recognises by name; raw `bgr8` frames
  are JPEG-compressed on the way, `jpeg` frames pass through untouched;
* `FaceDetections` can also be drawn over the image as
  `foxglove.ImageAnnotations` (`annotations()`), a derived channel.

A JSON-coded key's payload is kept byte for byte (it is validated, never
re-encoded), so a recording replays exactly what was published. Pure
apart from OpenCV, which is imported only when an image is converted.
"""

# No `from __future__ import annotations`: it would bind the name `annotations`,
# which `annotations()` below redefines (mypy: no-redef, and callers see a _Feature).
import base64
import json
from dataclasses import dataclass
from functools import cache
from typing import Any

import msgspec

from buddybot.contract import jpeg, keys
from buddybot.contract import messages as m
from buddybot.contract.schemas import json_schema

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
IMAGE_SCHEMA = "foxglove.CompressedImage"
ANNOTATIONS_SCHEMA = "foxglove.ImageAnnotations"
JPEG_QUALITY = 85
"""Quality of raw frames compressed for a recording or a viewer."""


class ChannelError(ValueError):
    """A payload that cannot become (or come back from) its channel's JSON."""


@dataclass(frozen=True)
class Channel:
    """One key's channel: the schema name, the schema text, and whether it is an image."""

    topic: keys.Topic
    schema_name: str
    schema: bytes
    image: bool

    @property
    def schema_encoding(self) -> str:
        return SCHEMA_ENCODING

    @property
    def message_encoding(self) -> str:
        return MESSAGE_ENCODING


def is_image(topic: keys.Topic) -> bool:
    return topic.type is m.Image


@cache
def channel(topic: keys.Topic) -> Channel:
    """The channel of a catalogue topic (cached: schemas are built once)."""
    if is_image(topic):
        return Channel(topic, IMAGE_SCHEMA, _json_bytes(_COMPRESSED_IMAGE), image=True)
    return Channel(topic, f"{keys.PREFIX_ROOT}.{topic.type.__name__}",
                   _json_bytes(message_schema(topic.type)), image=False)


def message_schema(msg_type: type[m.Message]) -> dict[str, Any]:
    """The JSON Schema of a message type, self-contained (no `$ref`)."""
    schema = json_schema(msg_type)
    defs = schema.pop("$defs", {})
    inlined = _inline(schema, defs, ())
    assert isinstance(inlined, dict)
    inlined["title"] = msg_type.__name__
    return inlined


def _inline(node: Any, defs: dict[str, Any], seen: tuple[str, ...]) -> Any:
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            name = ref.rsplit("/", 1)[-1]
            if name in seen:  # no message is recursive; refuse rather than loop
                raise ChannelError(f"recursive schema at {name}")
            return _inline(defs[name], defs, (*seen, name))
        return {k: _inline(v, defs, seen) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline(v, defs, seen) for v in node]
    return node


def _json_bytes(value: Any) -> bytes:
    return json.dumps(value, separators=(",", ":"), sort_keys=True).encode()


# --- payload <-> channel JSON ------------------------------------------------------


def to_json(topic: keys.Topic, payload: bytes | bytearray | memoryview) -> bytes:
    """A sample's wire payload -> the JSON its channel carries (ChannelError if invalid)."""
    try:
        msg = topic.codec.decode(payload, topic.type)
    except (msgspec.DecodeError, msgspec.ValidationError) as e:
        raise ChannelError(f"{topic.pattern}: {e}") from None
    if is_image(topic):
        return _json_bytes(compressed_image(msg))
    if topic.codec is keys.JSON:
        return bytes(payload)
    return msgspec.json.encode(msg)


def from_json(topic: keys.Topic, data: bytes | bytearray | memoryview) -> bytes:
    """Channel JSON -> the wire payload to publish on the key (ChannelError if invalid)."""
    try:
        if is_image(topic):
            msg: Any = image_from_compressed(msgspec.json.decode(data))
        else:
            msg = msgspec.json.decode(data, type=topic.type)
            if topic.codec is keys.JSON:
                return bytes(data)
    except (msgspec.DecodeError, msgspec.ValidationError) as e:
        raise ChannelError(f"{topic.pattern}: {e}") from None
    return topic.codec.encode(msg)


def decode(topic: keys.Topic, payload: bytes | bytearray | memoryview) -> Any:
    """A wire payload as its message (ChannelError if invalid)."""
    try:
        return topic.codec.decode(payload, topic.type)
    except (msgspec.DecodeError, msgspec.ValidationError) as e:
        raise ChannelError(f"{topic.pattern}: {e}") from None


# --- images --------------------------------------------------------------------


def jpeg_bytes(image: m.Image, quality: int = JPEG_QUALITY) -> bytes:
    """The image as a JPEG file: `jpeg` passes through, `bgr8` is compressed."""
    try:
        data = jpeg.from_image(image, quality)
    except jpeg.PixelsError as e:
        raise ChannelError(str(e)) from None
    if data is None:
        raise ChannelError("OpenCV could not compress the image")
    return data


def timestamp(stamp_ns: int) -> dict[str, int]:
    """Foxglove's time: whole seconds and nanoseconds."""
    sec, nsec = divmod(stamp_ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def compressed_image(image: m.Image, quality: int = JPEG_QUALITY) -> dict[str, Any]:
    """`foxglove.CompressedImage` JSON of an image (data base64, as JSON needs)."""
    return {
        "timestamp": timestamp(image.stamp_ns),
        "frame_id": image.frame_id,
        "data": base64.b64encode(jpeg_bytes(image, quality)).decode("ascii"),
        "format": "jpeg",
    }


def image_from_compressed(value: Any) -> m.Image:
    """`foxglove.CompressedImage` JSON -> a `jpeg` Image (its size read from the JPEG)."""
    if not isinstance(value, dict):
        raise ChannelError("a CompressedImage must be a JSON object")
    try:
        stamp = value["timestamp"]
        stamp_ns = int(stamp["sec"]) * 1_000_000_000 + int(stamp["nsec"])
        data = base64.b64decode(value["data"], validate=True)
        fmt = value.get("format", "jpeg")
        frame_id = str(value.get("frame_id", ""))
    except (KeyError, TypeError, ValueError) as e:
        raise ChannelError(f"not a CompressedImage: {e}") from None
    if fmt != "jpeg":
        raise ChannelError(f"CompressedImage format {fmt!r}: only jpeg is replayed")
    try:
        header = jpeg.read_header(data)
    except jpeg.JpegError as e:
        raise ChannelError(f"CompressedImage: {e}") from None
    try:
        return msgspec.convert({"stamp_ns": stamp_ns, "frame_id": frame_id,
                                "width": header.width, "height": header.height,
                                "encoding": "jpeg", "data": data}, m.Image)
    except msgspec.ValidationError as e:
        raise ChannelError(f"CompressedImage: {e}") from None


# --- face boxes as Foxglove annotations ----------------------------------------

_LINE_LOOP = 2
_POINTS = 1
_FOLLOWED = {"r": 0.1, "g": 0.9, "b": 0.2, "a": 1.0}
_OTHER = {"r": 1.0, "g": 0.75, "b": 0.1, "a": 1.0}
_CLEAR = {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.0}


def annotations(det: m.FaceDetections) -> dict[str, Any]:
    """`foxglove.ImageAnnotations` JSON: a box and keypoints per face, and a label
    with score (and distance and its main cue on the followed face)."""
    ts = timestamp(det.stamp_ns)
    points: list[dict[str, Any]] = []
    texts: list[dict[str, Any]] = []
    for face in det.faces:
        colour = _FOLLOWED if face.followed else _OTHER
        corners = [(face.x0, face.y0), (face.x1, face.y0), (face.x1, face.y1), (face.x0, face.y1)]
        points.append({"timestamp": ts, "type": _LINE_LOOP,
                       "points": [{"x": x, "y": y} for x, y in corners],
                       "outline_color": colour, "outline_colors": [], "fill_color": _CLEAR,
                       "thickness": 3.0 if face.followed else 2.0})
        if face.keypoints:
            points.append({"timestamp": ts, "type": _POINTS,
                           "points": [{"x": p.x, "y": p.y} for p in face.keypoints],
                           "outline_color": colour, "outline_colors": [], "fill_color": colour,
                           "thickness": 5.0})
        label = f"{face.score:.2f}"
        if face.followed and det.distance_m is not None:
            label += f"  {det.distance_m:.2f} m"
            used = sorted((c for c in det.cues if c.status == "used"), key=lambda c: -c.weight)
            if used:
                label += f" ({used[0].name})"
        texts.append({"timestamp": ts, "position": {"x": face.x0, "y": max(face.y0 - 4.0, 0.0)},
                      "text": label, "font_size": 14.0, "text_color": colour,
                      "background_color": {"r": 0.0, "g": 0.0, "b": 0.0, "a": 0.6}})
    return {"circles": [], "points": points, "texts": texts}


# --- the two Foxglove schemas, as JSON Schema -------------------------------------

_TIME = {"type": "object", "title": "time",
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
_COMPRESSED_IMAGE: dict[str, Any] = {
    "title": IMAGE_SCHEMA,
    "description": "A compressed image (Foxglove's schema)",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "data": {"type": "string", "contentEncoding": "base64"},
        "format": {"type": "string", "description": "jpeg"},
    },
}
_COLOR = {"type": "object", "properties": {c: {"type": "number"} for c in "rgba"}}
_POINT2 = {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}}
ANNOTATIONS_JSON_SCHEMA: dict[str, Any] = {
    "title": ANNOTATIONS_SCHEMA,
    "description": "Annotations drawn over an image (Foxglove's schema)",
    "type": "object",
    "properties": {
        "circles": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "position": _POINT2, "diameter": {"type": "number"},
            "thickness": {"type": "number"}, "fill_color": _COLOR, "outline_color": _COLOR}}},
        "points": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "type": {"type": "integer"},
            "points": {"type": "array", "items": _POINT2}, "outline_color": _COLOR,
            "outline_colors": {"type": "array", "items": _COLOR}, "fill_color": _COLOR,
            "thickness": {"type": "number"}}}},
        "texts": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "position": _POINT2, "text": {"type": "string"},
            "font_size": {"type": "number"}, "text_color": _COLOR,
            "background_color": _COLOR}}},
    },
}
ANNOTATIONS_SCHEMA_BYTES = _json_bytes(ANNOTATIONS_JSON_SCHEMA)
