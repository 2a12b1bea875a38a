"""What the renderer sends to its pages (services/eyes/wire.py), pure: the newest state
per slot, the message format and the WebSocket origin rule."""

from __future__ import annotations

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from buddybot.contract import messages as m
from buddybot.eyes import wire
from buddybot.runtime import endpoints


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


@pytest.mark.parametrize(("origin", "host", "allowed", "ok"), [
    (None, "127.0.0.1:8080", [], True),                          # not a browser: allowed
    ("http://127.0.0.1:8080", "127.0.0.1:8080", [], True),       # the server's own page
    ("HTTP://LocalHost:8080", "localhost:8080", [], True),       # case does not matter
    ("http://192.168.1.5", "192.168.1.5:80", [], True),          # default port spelled out
    ("https://eyes.example", "eyes.example", [], True),
    ("http://evil.example", "127.0.0.1:8080", [], False),        # another site
    ("http://127.0.0.1:9999", "127.0.0.1:8080", [], False),      # same host, other port
    ("https://127.0.0.1:8080", "127.0.0.1:8080", [], True),      # scheme only sets the port
    ("http://127.0.0.1:8080", None, [], False),                  # no Host: nothing to match
    ("null", "127.0.0.1:8080", [], False),                       # sandboxed frame, file://
    ("null", "127.0.0.1:8080", ["null"], True),
    ("file:///tmp/x.html", "127.0.0.1:8080", [], False),
    ("http://127.0.0.1:8080/path", "127.0.0.1:8080", [], False),
    ("http://user@127.0.0.1:8080", "127.0.0.1:8080", [], False),
    ("http://[::1", "127.0.0.1:8080", [], False),                # unparsable
    ("http://127.0.0.1:99999", "127.0.0.1:8080", [], False),
    ("http://tablet.local:8080", "127.0.0.1:8080", ["http://tablet.local:8080"], True),
    ("http://TABLET.local:8080", "127.0.0.1:8080", ["http://tablet.local:8080"], True),
    ("http://tablet.local", "127.0.0.1:8080", ["http://tablet.local:80"], True),
    ("https://tablet.local:8080", "127.0.0.1:8080", ["http://tablet.local:8080"], False),
    ("http://" + "a" * 5000, "127.0.0.1:8080", [], False),
])
def test_websocket_origin_rule(origin: str | None, host: str | None, allowed: list[str],
                               ok: bool) -> None:
    assert wire.origin_allowed(origin, host, allowed) is ok


@pytest.mark.parametrize(("origin", "host", "ok"), [
    ("http://127.0.0.1:8080", "127.0.0.1:8080", True),
    ("http://[::1]:8080", "[::1]:8080", True),
    ("http://192.168.1.5:8080", "192.168.1.5:8080", True),
    ("http://localhost:8080", "localhost:8080", True),
    ("http://buddy.local:8080", "buddy.local:8080", True),
    ("http://BUDDY:8080", "buddy:8080", True),
    # DNS rebinding: the attacker's name now points at the robot; Origin and
    # Host match, but the name is not the robot's.
    ("http://evil.example:8080", "evil.example:8080", False),
])
def test_own_origin_must_name_this_machine(origin: str, host: str, ok: bool) -> None:
    names = endpoints.host_names("Buddy.lan")
    assert names == {"localhost", "buddy.lan", "buddy", "buddy.local"}
    assert wire.origin_allowed(origin, host, (), names) is ok
    assert wire.origin_allowed("http://evil.example:8080", "evil.example:8080",
                               ["http://evil.example:8080"], names)   # unless listed


@given(st.text(max_size=300), st.text(max_size=60))
def test_origin_rule_never_raises(origin: str, host: str) -> None:
    assert wire.origin_allowed(origin, host, ["http://a:1", "http://[bad"]) in (True, False)
