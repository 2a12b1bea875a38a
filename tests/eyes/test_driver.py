"""The eyes driver's logic (services/eyes/driver.py), pure: gaze, pupil curve, lids."""

from __future__ import annotations

import math

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from buddybot.contract import messages as m
from buddybot.eyes import driver
from buddybot.eyes.settings import DEFAULT_PUPIL_CURVE, EyesSettings

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


VALID_CURVES = st.integers(1, 6).flatmap(lambda n: st.tuples(
    st.lists(st.floats(0, 1000), min_size=n, max_size=n, unique=True).map(sorted),
    st.lists(st.floats(0, 100), min_size=n, max_size=n).map(lambda p: sorted(p, reverse=True)),
)).map(lambda columns: list(zip(*columns, strict=True)))
"""Curves `from_points` accepts: 1 to 6 points, distances strictly increasing,
percentages within 0..100 never increasing (invalid ones: tested below)."""


@given(VALID_CURVES, st.floats(-10, 2000))
def test_any_valid_curve_stays_within_0_100(points: list[tuple[float, float]], d: float) -> None:
    curve = driver.PupilCurve.from_points(points)
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
