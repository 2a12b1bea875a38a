"""The dashboard's pure parts: history, image rate, node table, latency, requests."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.contract import messages as m
from buddybot.dashboard import model


def frames(t_ns: int, moving: int, still: int, radar_id: int = 0,
           gates: bool = True) -> m.LD2410TargetDataFrameArray:
    sensor = m.LD2410TargetDataFrame(
        radar_id=radar_id, target_state=m.TargetState.MOVING_AND_STATIONARY,
        movement_distance=moving, movement_energy=40, stationary_distance=still,
        stationary_energy=20, detection_distance=still,
        moving_gate_energy=list(range(0, 90, 10)) if gates else None,
        stationary_gate_energy=[5] * 9 if gates else None)
    return m.LD2410TargetDataFrameArray(stamp_ns=t_ns, device_id=1, sensors=[sensor])


def test_history_keeps_only_its_span_and_never_goes_back() -> None:
    h = model.History(span_s=10.0)
    for t in range(30):
        h.add(float(t), t, 2 * t)
    assert [p[0] for p in h.points()] == [float(t) for t in range(19, 30)]
    h.add(5.0, 1, 1)  # a late frame joins the end, at the end's time
    assert h.points()[-1] == (29.0, 1, 1)
    h.trim(100.0)
    assert len(h) == 0


def test_radar_history_per_sensor_and_bounded() -> None:
    r = model.RadarHistory(span_s=30.0, max_sensors=2)
    for radar_id in range(3):
        r.add(1.0, frames(1_000_000_000, 100, 120, radar_id=radar_id))
    snap = r.snapshot(2.0)
    assert sorted(snap) == ["1/1", "1/2"]  # the oldest sensor was forgotten
    assert snap["1/2"] == [(1.0, 100, 120)]


def test_radar_view_says_basic_mode_by_missing_gates() -> None:
    eng = model.radar_view(1.0, frames(1, 150, 160))[0]
    assert eng["moving_gates"] == [0, 10, 20, 30, 40, 50, 60, 70, 80]
    assert eng["state"] == "MOVING_AND_STATIONARY" and eng["sensor"] == "1/0"
    basic = model.radar_view(1.0, frames(1, 150, 160, gates=False))[0]
    assert basic["moving_gates"] is None and basic["still_gates"] is None


def test_rate_limiter_gives_the_rate_without_bursts() -> None:
    limiter = model.RateLimiter(10.0)
    # 15 fps for 10 s: 10 fps out, not the 7.5 of "at least 100 ms apart".
    allowed = sum(limiter.allow(i / 15.0) for i in range(150))
    assert 99 <= allowed <= 101
    # A long pause buys no burst: 30 fps right after it still gives ~10 fps.
    after = sum(limiter.allow(100.0 + i / 30.0) for i in range(30))
    assert 10 <= after <= 11
    with pytest.raises(ValueError):
        model.RateLimiter(0.0)


def test_image_frame_round_trip() -> None:
    header = {"stamp_ns": 5, "frame_id": "cam", "width": 4, "height": 2}
    packed = model.pack_image(header, b"\xff\xd8jpeg")
    assert model.unpack_image(packed) == (header, b"\xff\xd8jpeg")


def test_node_table_alive_down_and_restarts() -> None:
    t = model.NodeTable()
    assert t.update({"camera": {"a"}, "eyes": {"e"}}, 1.0)
    assert not t.update({"camera": {"a"}, "eyes": {"e"}}, 2.0)  # nothing new
    assert t.update({"eyes": {"e"}}, 3.0)                    # camera died
    cam = t.get("camera")
    assert cam is not None and not cam.alive and cam.since_s == 3.0 and cam.restarts == 0
    t.update({"camera": {"b"}, "eyes": {"e"}}, 4.0)          # back, new instance
    assert cam.alive and cam.restarts == 1 and cam.since_s == 4.0
    t.update({"camera": {"b", "c"}, "eyes": {"e"}}, 5.0)     # a second process
    assert cam.restarts == 2 and cam.view()["instances"] == ["b", "c"]
    rows = {r["name"]: r for r in t.view()}
    assert rows["eyes"]["alive"] and rows["eyes"]["restarts"] == 0


def test_a_stopped_app_leaves_the_list_and_a_configured_node_stays_down() -> None:
    """An app that stopped has left: dropped `gone_after_s` after it went down. A node
    the config runs should be running: it stays listed as down."""
    t = model.NodeTable(keep=frozenset({"camera", "greeter"}), gone_after_s=10.0)
    t.update({"camera": {"a"}, "greeter": {"g"}, "doorbell": {"d"}}, 1.0)
    assert t.update({}, 2.0)                                  # everyone stopped
    assert {r["name"]: r["alive"] for r in t.view()} == {
        "camera": False, "doorbell": False, "greeter": False}
    assert not t.update({}, 11.9)                             # not yet 10 s down
    assert t.update({}, 12.0)                                 # the doorbell app left
    assert [r["name"] for r in t.view()] == ["camera", "greeter"]
    assert not t.update({}, 1000.0)                           # configured: stays down
    assert [r["alive"] for r in t.view()] == [False, False]


def test_an_app_restarted_soon_keeps_its_row_and_counts_the_restart() -> None:
    t = model.NodeTable(gone_after_s=10.0)
    t.update({"doorbell": {"d1"}}, 1.0)
    t.update({}, 2.0)
    t.update({"doorbell": {"d2"}}, 5.0)                       # back within 10 s
    row = t.get("doorbell")
    assert row is not None and row.alive and row.restarts == 1
    t.update({}, 6.0)
    t.update({}, 16.0)
    assert t.get("doorbell") is None
    t.update({"doorbell": {"d3"}}, 17.0)                      # a new visit: a new row
    again = t.get("doorbell")
    assert again is not None and again.restarts == 0


def test_node_table_diagnostics_and_bound() -> None:
    t = model.NodeTable(max_nodes=2)
    diag = m.DiagnosticStatus(stamp_ns=1, node="camera", level="WARN", message="x" * 500)
    assert t.diagnostics(diag, 1.0)
    assert not t.diagnostics(diag, 2.0)  # same level and message
    row = t.get("camera")
    assert row is not None and row.level == "WARN" and len(row.message) < 300
    assert not row.alive  # diagnostics alone do not make a node alive
    t.update({"a": {"1"}, "b": {"2"}}, 3.0)
    assert len(t.view()) == 2


def test_latency_percentiles() -> None:
    lat = model.Latency(window=100)
    assert lat.view()["p95_ms"] is None
    for ms in range(1, 201):
        lat.add(float(ms))
    v = lat.view()
    assert v["n"] == 100 and v["last_ms"] == 200.0
    assert v["p50_ms"] == 150.0 and v["p95_ms"] == 195.0


def test_outbox_keeps_newest_per_slot_and_appends_frames_bounded() -> None:
    box = model.Outbox()
    box.put("presence", 1)
    box.put("faces", "f")
    box.put("presence", 2)
    box.put_frames([{"n": i} for i in range(model.MAX_QUEUED_FRAMES + 5)])
    out = box.take()
    assert out[0] == ("faces", "f") and out[1] == ("presence", 2)
    assert out[2][0] == "radar" and len(out[2][1]) == model.MAX_QUEUED_FRAMES
    assert out[2][1][0] == {"n": 5} and box.dropped_frames == 5
    assert not box and box.take() == []


@pytest.mark.parametrize(("text", "kind"), [
    ('{"op": "expression", "action": "EYE_GRIN", "id": 3}', model.SetExpression),
    ('{"op": "play", "sound": "greeting"}', model.PlaySound),
    ('{"op": "stop"}', model.StopSound),
    ('{"op": "control", "on": true}', model.Control),
    ('{"op": "gaze", "yaw": 0.5, "pitch": -0.35, "id": 9}', model.Look),
    ('{"op": "break", "lease_id": "L7"}', model.BreakLease),
])
def test_commands_parse(text: str, kind: type) -> None:
    assert isinstance(model.parse_command(text), kind)


@pytest.mark.parametrize("text", [
    "not json", "{}", '{"op": "explode"}', '{"op": "expression", "action": "EYE_WINK"}',
    '{"op": "expression", "action": 3}', '{"op": "play", "sound": ""}',
    '{"op": "stop", "extra": 1}', "[" * 5000,
    '{"op": "control"}', '{"op": "control", "on": "yes"}',
    '{"op": "gaze", "yaw": 7, "pitch": 0}', '{"op": "gaze", "yaw": NaN, "pitch": 0}',
    '{"op": "gaze", "yaw": 0}', '{"op": "break", "lease_id": ""}',
    '{"op": "break", "lease_id": "' + "x" * 65 + '"}',
])
def test_bad_commands_get_one_line_reasons(text: str) -> None:
    with pytest.raises(model.BadCommand) as err:
        model.parse_command(text)
    assert "\n" not in str(err.value) and len(str(err.value)) < 600


def params(**values: object) -> m.ParamReply:
    return m.ParamReply(node="n", table="t", params=[
        m.ParamInfo(name=k, value=v, type="float", range="", live=True) for k, v in values.items()])


def test_presence_rules_from_params() -> None:
    rules = model.presence_rules(params(range_m=2.0, exit_margin_m=0.3, absence_hold_s=5,
                                        target_hold_s=1.5, stale_after_s=1.0))
    assert rules == {"range_m": 2.0, "exit_margin_m": 0.3, "absence_hold_s": 5.0,
                     "target_hold_s": 1.5}
    assert model.presence_rules(params(exit_margin_m=0.3)) is None
    assert model.presence_rules(params(range_m=True)) is None
    refused = params(range_m=2.0)
    refused.error = "no"
    assert model.presence_rules(refused) is None


def test_sound_names_from_the_service_else_the_config() -> None:
    live = m.ParamReply(node="audio", table="audio", params=[m.ParamInfo(
        name="sounds", value={"hello": "a.wav", "bye": "b.wav"}, type="dict", range="",
        live=False)])
    assert model.sound_names(live, {"greeting": "x"}) == ["bye", "hello"]
    assert model.sound_names(None, {"greeting": "x", "farewell": "y"}) == ["farewell", "greeting"]


@pytest.mark.parametrize(("configured", "host", "expected"), [
    ("http://eyes.local:9000/eyes?eye=left", "robot:8090", "http://eyes.local:9000/eyes?eye=left"),
    ("", "buddy.local:8090", "http://buddy.local:8080/eyes?eye=both"),
    ("", "192.168.1.20:8090", "http://192.168.1.20:8080/eyes?eye=both"),
    ("", "[::1]:8090", "http://[::1]:8080/eyes?eye=both"),
    ("", None, "http://127.0.0.1:8080/eyes?eye=both"),
])
def test_eye_page_url(configured: str, host: str | None, expected: str) -> None:
    assert model.eye_page_url(configured, 8080, host) == expected


def test_enum_names_are_json_ready() -> None:
    names = msgspec.json.decode(msgspec.json.encode(model.enum_names()))
    assert names["ExpressionAction"]["3"] == "EYE_GRIN"
    assert names["PresenceState"]["1"] == "IN_RANGE"


def lease(lease_id: str, holder: str, priority: m.LeasePriority = "app",
          expires_ns: int | None = None) -> m.Lease:
    return m.Lease(lease_id=lease_id, holder=holder, instance="z1", priority=priority,
                   resources=["expression", "gaze"], granted_ns=2_000_000_000,
                   expires_ns=expires_ns)


def test_the_lease_panel_marks_our_lease_and_lists_the_ended_newest_first() -> None:
    state = m.Leases(stamp_ns=5, leases=[lease("L1", "greeter", expires_ns=9_000_000_000),
                                         lease("L2", "dashboard", "operator")],
                     ended=[m.LeaseEnd(lease_id="L0", holder="old", reason="expired",
                                       stamp_ns=1_000_000_000),
                            m.LeaseEnd(lease_id="L9", holder="app", reason="preempted",
                                       stamp_ns=3_000_000_000, message="by dashboard")])
    view = model.leases_view(state, "L2")
    assert view["known"] and view["holding"] and view["own"] == "L2"
    assert [(r["lease_id"], r["own"]) for r in view["leases"]] == [("L1", False), ("L2", True)]
    assert view["leases"][0]["expires"] == 9.0 and view["leases"][1]["expires"] is None
    assert view["leases"][0]["since"] == 2.0
    assert [e["reason"] for e in view["ended"]] == ["preempted", "expired"]
    assert view["ended"][0]["message"] == "by dashboard"
    msgspec.json.encode(view)  # what the page gets is plain JSON
    idle = model.leases_view(state, None)
    assert not idle["holding"] and not any(r["own"] for r in idle["leases"])


def test_no_lease_state_says_so() -> None:
    view = model.leases_view(None, None)
    assert view == {"known": False, "holding": False, "own": None, "leases": [], "ended": []}
