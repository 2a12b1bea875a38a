"""Pure logic of the eyes: driver mapping, pupil curve, lids, placement, wire state, kiosk argv."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from buddybot.contract import messages as m
from buddybot.eyes import driver, kiosk, placement, wire
from buddybot.eyes.placement import Display, PlacementError, Request, plan
from buddybot.eyes.settings import DEFAULT_PUPIL_CURVE, EyeRendererSettings, EyesSettings
from buddybot.runtime import endpoints

A = m.ExpressionAction
CURVE = driver.PupilCurve.from_points(DEFAULT_PUPIL_CURVE)


def control(
    yaw: float = 0.0, pitch: float = 0.0, cm: float = 100.0, stamp: int = 123
) -> m.EyeControl:
    return m.EyeControl(stamp_ns=stamp, yaw=yaw, pitch=pitch, target_distance_cm=cm)


# --- gaze -------------------------------------------------------------------------------


@pytest.mark.parametrize(("yaw", "pitch", "yaw_deg", "pitch_deg"), [
    (0.0, 0.0, 0.0, 0.0),
    (math.pi / 6, 0.0, 30.0, 0.0),        # +yaw = robot's left stays positive
    (-math.pi / 4, math.pi / 12, -45.0, 15.0),
    (0.1, -0.2, math.degrees(0.1), math.degrees(-0.2)),
    (3.15, 1.58, 180.0, 90.0),            # message limits clamp into the degree range
    (-3.15, -1.58, -180.0, -90.0),
])
def test_direction_is_degrees_with_the_same_signs(
    yaw: float, pitch: float, yaw_deg: float, pitch_deg: float
) -> None:
    out = driver.direction_from_control(control(yaw, pitch, stamp=987654321))
    assert out.yaw == pytest.approx(yaw_deg)
    assert out.pitch == pytest.approx(pitch_deg)
    assert out.stamp_ns == 987654321
    # What the driver produces is always a valid message on the wire.
    msgspec.json.decode(msgspec.json.encode(out), type=m.EyesDirection)


@pytest.mark.parametrize(("cm", "expected"), [(45.5, 45.5), (250.0, 250.0), (0.0, None)])
def test_direction_carries_the_target_distance_for_vergence(
    cm: float, expected: float | None
) -> None:
    """The pages converge the eyes on a near face; 0 ("unknown") becomes None."""
    out = driver.direction_from_control(control(0.1, 0.0, cm=cm))
    assert out.target_distance_cm == expected
    wire_text = msgspec.json.encode(out)
    assert msgspec.json.decode(wire_text, type=m.EyesDirection) == out


def test_direction_without_a_distance_is_accepted() -> None:
    bare = b'{"stamp_ns": 5, "yaw": 1.0, "pitch": 2.0}'
    assert msgspec.json.decode(bare, type=m.EyesDirection).target_distance_cm is None


# --- pupil ------------------------------------------------------------------------------


def test_default_curve_near_large_far_small() -> None:
    assert CURVE(30) == pytest.approx(75.0)
    assert CURVE(100) == pytest.approx(55.0)
    assert CURVE(300) == pytest.approx(30.0)
    assert CURVE(65) == pytest.approx(65.0)         # linear between points
    assert CURVE(5) == pytest.approx(75.0)          # flat before the first point
    assert CURVE(10_000) == pytest.approx(30.0)     # flat after the last
    assert CURVE(math.inf) == pytest.approx(30.0)


@given(st.floats(0, 70_000), st.floats(0, 70_000))
def test_default_curve_is_monotonic_and_clamped(a: float, b: float) -> None:
    near, far = sorted((a, b))
    assert 0.0 <= CURVE(far) <= CURVE(near) <= 100.0


@given(st.lists(st.tuples(st.floats(0, 1000), st.floats(-50, 150)), min_size=1, max_size=6),
       st.floats(-10, 2000))
def test_any_valid_curve_stays_within_0_100(points: list[tuple[float, float]], d: float) -> None:
    try:
        curve = driver.PupilCurve.from_points(points)
    except ValueError:
        return  # invalid user curves are refused, tested below
    assert 0.0 <= curve(d) <= 100.0


@pytest.mark.parametrize(("points", "message"), [
    ([], "at least one point"),
    ([[10, 50, 3]], "must be [distance_cm, percent]"),
    ([[10, 150]], "within 0..100"),
    ([[-1, 50]], ">= 0"),
    ([[100, 50], [50, 40]], "distances must increase"),
    ([[10, 20], [50, 40]], "must not grow"),
    ([[float("nan"), 40]], "finite"),
])
def test_bad_curves_are_refused_with_a_reason(points: list[list[float]], message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        driver.PupilCurve.from_points(points)


def test_settings_default_curve_matches_driver_default() -> None:
    assert [tuple(p) for p in EyesSettings().pupil_curve] == list(DEFAULT_PUPIL_CURVE)


def test_pupil_keeps_stamp_and_handles_unknown_distance() -> None:
    near = driver.pupil_from_control(control(cm=40, stamp=5), CURVE, 50.0)
    far = driver.pupil_from_control(control(cm=250, stamp=6), CURVE, 50.0)
    assert near.dilation_percentage > far.dilation_percentage
    assert (near.stamp_ns, far.stamp_ns) == (5, 6)
    unknown = driver.pupil_from_control(control(cm=0), CURVE, 42.0)
    assert unknown.dilation_percentage == 42.0


# --- lids -------------------------------------------------------------------------------


def test_every_expression_has_valid_lids_and_the_seed_values() -> None:
    assert set(driver.DEFAULT_LIDS) == set(A)
    for action in A:
        msgs = driver.lids_for_expression(m.ScreenExpression(stamp_ns=77, action=action))
        assert [x.eye_id for x in msgs] == [m.EyeId.BOTH]
        for msg in msgs:
            assert msg.stamp_ns == 77
            msgspec.json.decode(msgspec.json.encode(msg), type=m.EyeLidControl)
    awake = driver.lids_for_expression(m.ScreenExpression(stamp_ns=1, action=A.EYE_AWAKE))[0]
    sleep = driver.lids_for_expression(m.ScreenExpression(stamp_ns=1, action=A.EYE_SLEEP))[0]
    assert (awake.top_lid_position, awake.bottom_lid_position) == (0.0, 0.0)
    assert (sleep.top_lid_position, sleep.bottom_lid_position) == (50.0, 50.0)


def test_expressions_read_at_a_glance() -> None:
    lids = {a: driver.DEFAULT_LIDS[a].left for a in A}
    # Only SLEEP closes the eye; SLEEPY has the heaviest top lid of the open ones.
    closed = [a for a, x in lids.items() if x.top + x.bottom >= 100]
    assert closed == [A.EYE_SLEEP]
    open_tops = {a: x.top for a, x in lids.items() if a != A.EYE_SLEEP}
    assert max(open_tops, key=open_tops.__getitem__) == A.EYE_SLEEPY
    # GRIN: the bottom lid rises (happy crescent), the top stays up.
    assert lids[A.EYE_GRIN].bottom > 20 and lids[A.EYE_GRIN].top == 0
    # SAD: a lowered top lid, but less than sleepy.
    assert 0 < lids[A.EYE_SAD].top < lids[A.EYE_SLEEPY].top


def test_lid_overrides_and_asymmetric_eyes() -> None:
    table = driver.lid_table({"EYE_SAD": [30, 5], "EYE_GRIN": [0, 30, 10, 30]})
    assert table[A.EYE_SAD] == driver.EyePair.same(30, 5)
    msgs = driver.lids_for_expression(m.ScreenExpression(stamp_ns=9, action=A.EYE_GRIN), table)
    assert [(x.eye_id, x.top_lid_position) for x in msgs] == [
        (m.EyeId.LEFT, 0.0), (m.EyeId.RIGHT, 10.0)]
    assert table[A.EYE_AWAKE] == driver.DEFAULT_LIDS[A.EYE_AWAKE]


@pytest.mark.parametrize(("overrides", "message"), [
    ({"EYE_WINK": [0, 0]}, "unknown expression"),
    ({"EYE_SAD": [0, 0, 0]}, "give"),
    ({"EYE_SAD": [0, 101]}, "within 0..100"),
])
def test_bad_lid_overrides_are_refused(overrides: dict[str, list[float]], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        driver.lid_table(overrides)


# --- placement --------------------------------------------------------------------------

D1 = Display(0, 0, 800, 480, "HDMI-1")
D2 = Display(800, 0, 800, 480, "HDMI-2")
D3 = Display(1600, 0, 1024, 600, "DP-1")


def windows(displays: list[Display], request: Request | None = None) -> list[tuple[str, int]]:
    return [(w.eye, w.display_number) for w in plan(displays, request or Request())]


def test_default_two_displays_left_on_1_right_on_2() -> None:
    assert windows([D1, D2]) == [("left", 1), ("right", 2)]
    # Numbered left to right whatever order the OS lists them in.
    assert plan([D2, D1])[0].display == D1
    assert windows([D3, D2, D1]) == [("left", 1), ("right", 2)]


def test_one_display_no_option_both_eyes_on_it() -> None:
    (win,) = plan([D2])
    assert (win.eye, win.display_number, win.display) == ("both", 1, D2)


def test_no_display_is_an_error() -> None:
    with pytest.raises(PlacementError, match=r"no display found.*--no-browser"):
        plan([])
    with pytest.raises(PlacementError, match="no display"):
        plan([], Request(eyes=("left",)))


def test_more_eyes_configured_than_displays_is_an_error() -> None:
    with pytest.raises(PlacementError, match=r"2 eyes configured .* only 1 display"):
        plan([D1], Request(eyes=("left", "right")))
    with pytest.raises(PlacementError, match="2 eyes configured"):
        plan([D1], Request(left_display=1))


def test_display_number_that_does_not_exist_is_an_error() -> None:
    with pytest.raises(PlacementError, match="right eye configured on display 3 but only 2"):
        plan([D1, D2], Request(right_display=3))
    with pytest.raises(PlacementError, match="left eye configured on display 0"):
        plan([D1, D2], Request(left_display=0))


def test_options_choose_displays_and_eyes() -> None:
    assert windows([D1, D2], Request(left_display=2, right_display=1)) == [
        ("left", 2), ("right", 1)]
    assert windows([D1, D2, D3], Request(right_display=3)) == [("left", 1), ("right", 3)]
    assert windows([D1, D2, D3], Request(left_display=2)) == [("left", 2), ("right", 1)]
    assert windows([D1], Request(eyes=("right",))) == [("right", 1)]
    assert windows([D1, D2], Request(eyes=("left",), left_display=2)) == [("left", 2)]
    # Both explicitly on one display: one window with both eyes.
    assert windows([D1, D2], Request(left_display=2, right_display=2)) == [("both", 2)]
    assert windows([D1], Request(left_display=1, right_display=1)) == [("both", 1)]


def test_geometry_parsing() -> None:
    d = placement.parse_geometry("1024x600+1920+0")
    assert (d.width, d.height, d.x, d.y) == (1024, 600, 1920, 0)
    for bad in ("1024x600", "axb+0+0", "0x600+0+0", "", "10x10+1+2+3"):
        with pytest.raises(ValueError, match="WIDTHxHEIGHT"if bad != "0x600+0+0" else "positive"):
            placement.parse_geometry(bad)


# --- wire state and kiosk argv ------------------------------------------------------------


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


def test_kiosk_command_positions_an_app_window_on_its_display(tmp_path: Path) -> None:
    win = placement.Window("right", 2, D2)
    argv = kiosk.command("/usr/bin/chromium", kiosk.page_url("http://127.0.0.1:8080/", "right"),
                         win, tmp_path / "right", ["--disable-gpu"])
    assert argv[0] == "/usr/bin/chromium"
    assert "--app=http://127.0.0.1:8080/eyes?eye=right" in argv
    assert "--window-position=800,0" in argv and "--window-size=800,480" in argv
    assert "--kiosk" in argv and f"--user-data-dir={tmp_path / 'right'}" in argv
    assert argv[-1] == "--disable-gpu"


def test_find_browser_explicit_missing_is_none() -> None:
    assert kiosk.find_browser("/nonexistent/chromium") is None


# --- WebSocket origin and renderer limits --------------------------------------------


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


@pytest.mark.parametrize(("table", "message"), [
    ({"max_pages": 0}, "max_pages"),
    ({"max_pages": 100000}, "max_pages"),
    ({"page_stall_s": 0}, "page_stall_s"),
    ({"allowed_origins": ["evil.example"]}, "allowed_origins"),
    ({"allowed_origins": ["http://a.example/path"]}, "allowed_origins"),
])
def test_renderer_limits_are_range_checked(table: dict[str, object], message: str) -> None:
    with pytest.raises(msgspec.ValidationError, match=message):
        msgspec.convert(table, EyeRendererSettings)
    assert EyeRendererSettings().max_pages == 16


def test_status_message_is_in_the_page_format() -> None:
    assert wire.encode("status", wire.Status(bus=True)) == '{"topic":"status","msg":{"bus":true}}'


def test_inbox_hands_the_loop_only_the_newest_per_slot() -> None:
    """A flood from another thread reaches the loop as a few small batches with
    the newest value of each slot, in arrival order; nothing queues per sample."""
    from buddybot.eyes.renderer import Inbox

    batches: list[list[m.Message]] = []

    async def scenario() -> Inbox:
        loop = asyncio.get_running_loop()
        done = asyncio.Event()
        inbox = Inbox(loop, lambda batch: (batches.append(batch), done.set()))

        def flood() -> None:
            for i in range(20_000):
                inbox.put(m.EyesDirection(stamp_ns=i, yaw=i % 90, pitch=0.0))
                if i % 1000 == 0:
                    inbox.put(m.PupilControl(stamp_ns=i, dilation_percentage=i % 100))
            inbox.put(m.EyesDirection(stamp_ns=99_999, yaw=1.0, pitch=2.0))

        await loop.run_in_executor(None, flood)
        while not batches or batches[-1][-1].stamp_ns != 99_999:
            done.clear()
            await asyncio.wait_for(done.wait(), 10)
        return inbox

    inbox = asyncio.run(scenario())
    assert inbox.received == 20_000 + 20 + 1
    assert sum(len(b) for b in batches) + inbox.coalesced == inbox.received
    assert all(len(b) <= 2 for b in batches)          # one per slot, never a backlog
    assert len(batches) < 2_000                      # not one wake-up per sample
    assert batches[-1][-1] == m.EyesDirection(stamp_ns=99_999, yaw=1.0, pitch=2.0)
