"""The people service and radar presence read an LD2410 frame's distance by the
one rule of the contract (`messages.target_distance_cm`): they never disagree
on where a sensor's target is."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from buddybot.contract import messages as m
from buddybot.people.service import ranges_seen
from buddybot.radar.presence import Reading

cm = st.integers(min_value=0, max_value=1000)


def frame(state: int, detection: int, moving: int, still: int) -> m.LD2410TargetDataFrame:
    return m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState(state),
                                   movement_distance=moving, movement_energy=50,
                                   stationary_distance=still, stationary_energy=50,
                                   detection_distance=detection)


def test_the_rule_on_the_frames_real_modules_send() -> None:
    assert m.target_distance_cm(m.TargetState.MOVING, 120, 80, 0) == 120
    assert m.target_distance_cm(m.TargetState.MOVING, 0, 80, 60) == 80  # 0 cm: the kind's
    assert m.target_distance_cm(m.TargetState.STATIONARY, 0, 80, 60) == 60
    assert m.target_distance_cm(m.TargetState.MOVING_AND_STATIONARY, 0, 80, 60) == 80
    for silent in (m.TargetState.NO_TARGET, m.TargetState.NOISE_DETECTING):
        assert m.target_distance_cm(silent, 120, 80, 60) == 0


@given(st.sampled_from(list(m.TargetState)), cm, cm, cm)
def test_people_and_radar_presence_read_the_same_distance(state: int, detection: int,
                                                          moving: int, still: int) -> None:
    (seen,) = ranges_seen(m.LD2410TargetDataFrameArray(
        stamp_ns=1, device_id="0", sensors=[frame(state, detection, moving, still)]))
    reading = Reading(state, detection, moving, still)
    if reading.present and reading.distance_m > 0:
        assert seen.distance_m == reading.distance_m
    else:
        assert seen.distance_m is None
