"""`buddybot echo` output: one line of valid JSON whatever the wire carries."""

from __future__ import annotations

import json

import msgspec

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.contract.describe import describe


def test_image_summary_is_valid_json_for_any_frame_id() -> None:
    # frame_id is free text from the wire: a quote, a backslash or a newline
    # must be escaped, not pasted into the output.
    frame_id = 'cam "front"\\left\nrow'
    image = m.Image(stamp_ns=5, frame_id=frame_id, width=2, height=1, encoding="bgr8",
                    data=b"\x00" * 6)
    line = describe(keys.absolute("buddy", "camera/front/image"), msgspec.msgpack.encode(image))

    assert "\n" not in line
    parsed = json.loads(line)
    assert parsed["frame_id"] == frame_id
    assert parsed == {"type": "Image", "stamp_ns": 5, "frame_id": frame_id, "width": 2,
                      "height": 1, "encoding": "bgr8", "data": "<6 bytes>"}
