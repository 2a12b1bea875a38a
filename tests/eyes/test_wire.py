"""What the renderer sends to its pages (services/eyes/wire.py), pure: the newest state
per slot and the message format."""

from __future__ import annotations

import msgspec

from buddybot.contract import messages as m
from buddybot.eyes import wire


def lids(eye: m.EyeId, top: float) -> m.EyeLidControl:
    return m.EyeLidControl(stamp_ns=1, eye_id=eye, top_lid_position=top, bottom_lid_position=0)


def test_latest_state_keeps_newest_per_slot_in_arrival_order() -> None:
    state = wire.LatestState()
    state.put_message(m.EyesDirection(stamp_ns=1, yaw=1, pitch=0))
    state.put_message(lids(m.EyeId.LEFT, 10))
    state.put_message(m.EyesDirection(stamp_ns=2, yaw=2, pitch=0))
    assert [msgspec.json.decode(t)["topic"] for t in state.snapshot()] == ["lids", "direction"]
    assert msgspec.json.decode(state.snapshot()[-1])["msg"] == {
        "stamp_ns": 2, "yaw": 2.0, "pitch": 0.0, "target_distance_cm": None}
    state.put_message(lids(m.EyeId.BOTH, 50))     # supersedes the per-eye value
    assert [s for s, _ in state.items()] == ["direction", "lids:2"]
    state.put_message(lids(m.EyeId.RIGHT, 20))    # a later per-eye message applies after BOTH
    assert [s for s, _ in state.items()] == ["direction", "lids:2", "lids:1"]
    assert len(state.take()) == 3 and len(state) == 0


def test_status_message_is_in_the_page_format() -> None:
    assert wire.encode("status", wire.Status(bus=True)) == '{"topic":"status","msg":{"bus":true}}'


