"""Target choice and One-Euro smoothing (pure, time passed in)."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera.tracking import OneEuro, PointSmoother, TargetTracker


def face(cx: float, cy: float, size: float, score: float = 0.9) -> bf.Detection:
    h = size / 2
    return bf.Detection((cx - h, cy - h, cx + h, cy + h), score, np.zeros((6, 2), np.float32))


def test_one_euro_removes_jitter_of_a_still_value() -> None:
    rng = np.random.default_rng(1)
    f = OneEuro(min_cutoff=1.0, beta=0.5)
    raw = 1.0 + rng.normal(0, 0.02, 300)
    out = np.array([f(float(x), i / 30) for i, x in enumerate(raw)])
    assert np.std(out[30:]) < np.std(raw[30:]) / 3


def test_one_euro_follows_a_moving_value_with_little_lag() -> None:
    f = OneEuro(min_cutoff=1.0, beta=2.0)
    t = np.arange(90) / 30
    out = [f(float(0.5 * ti), float(ti)) for ti in t]  # 0.5 m/s ramp
    assert out[-1] == pytest.approx(0.5 * t[-1], abs=0.05)


def test_one_euro_ignores_a_repeated_stamp() -> None:
    f = OneEuro()
    assert f(1.0, 1.0) == 1.0
    assert f(5.0, 1.0) == 1.0


def test_point_smoother_restarts_after_a_gap() -> None:
    s = PointSmoother(reset_after_s=0.5)
    s((1.0, 0.0, 0.0), 0.0)
    s((1.0, 0.0, 0.0), 0.033)
    assert s((3.0, 1.0, 1.0), 2.0) == (3.0, 1.0, 1.0)


def test_first_choice_is_the_largest_face() -> None:
    tr = TargetTracker()
    chosen, new = tr.select([face(100, 100, 60), face(400, 100, 120)], 0.0)
    assert chosen is not None and chosen.centre[0] == 400 and new


def test_stays_with_the_same_person_when_another_gets_bigger() -> None:
    tr = TargetTracker()
    tr.select([face(100, 100, 100), face(400, 100, 80)], 0.0)
    for i in range(1, 60):
        t = i / 30
        # person B walks closer and becomes much larger; A moves a little
        chosen, new = tr.select([face(400, 100, 80 + 3 * i), face(100 + i, 100, 100)], t)
        assert chosen is not None and chosen.centre[0] == 100 + i and not new
    assert tr.target_changes == 1


def test_a_missed_frame_does_not_make_the_target_jump() -> None:
    tr = TargetTracker(switch_after_s=0.5)
    tr.select([face(100, 100, 100), face(400, 100, 80)], 0.0)
    chosen, _ = tr.select([face(400, 100, 80)], 0.033)  # A missed for one frame
    assert chosen is None
    chosen, new = tr.select([face(102, 100, 100), face(400, 100, 80)], 0.066)
    assert chosen is not None and chosen.centre[0] == 102 and not new


def test_switches_when_the_target_has_really_gone() -> None:
    tr = TargetTracker(switch_after_s=0.5)
    tr.select([face(100, 100, 100), face(400, 100, 80)], 0.0)
    chosen = None
    for i in range(1, 30):
        chosen, new = tr.select([face(400, 100, 80)], i / 30)
        if chosen is not None:
            assert new and i / 30 >= 0.5
            break
    assert chosen is not None and chosen.centre[0] == 400
    assert tr.target_changes == 2


def test_no_faces_no_target() -> None:
    assert TargetTracker().select([], 0.0) == (None, False)


FUTURE = (2**63 - 1) * 1e-9  # the largest stamp a message can carry, in seconds


@pytest.mark.parametrize("wrong_t", [FUTURE, 15.0, 0.9])
def test_one_stamp_from_the_future_does_not_freeze_the_smoothed_point(wrong_t: float) -> None:
    """The filters hold for stamps older than their last one: after a wrong stamp ahead
    they must start afresh, not hold until real time catches up with it."""
    s = PointSmoother(reset_after_s=0.5)
    for i in range(10):
        s((1.0, 0.0, 0.0), i / 30)
    s((1.0, 0.0, 0.0), wrong_t)
    out = [s((1.0, 0.5, 0.0), 0.4 + i / 30) for i in range(5)]
    assert out[-1][1] == pytest.approx(0.5, abs=0.05)


def test_time_going_backwards_restarts_the_smoothing_and_a_repeat_does_not() -> None:
    s = PointSmoother(reset_after_s=0.5)
    s((1.0, 0.0, 0.0), 1.0)
    assert s((2.0, 0.0, 0.0), 1.0)[0] == 1.0  # same stamp: no time passed, held
    assert s((2.0, 0.0, 0.0), 0.99)[0] == 2.0  # older: a fresh start, never a hold
    assert 2.0 < s((3.0, 0.0, 0.0), 1.02)[0] < 3.0  # and smoothed again after it


def test_a_sighting_stamped_in_the_future_does_not_hold_the_choice_forever() -> None:
    tr = TargetTracker(switch_after_s=0.5)
    tr.select([face(100, 100, 100)], 0.0)
    tr.select([face(101, 100, 100)], FUTURE)  # a frame with a wrong stamp
    chosen = None
    for i in range(1, 30):
        chosen, new = tr.select([face(400, 100, 80)], 0.1 + i / 30)
        if chosen is not None:
            break
    assert chosen is not None and chosen.centre[0] == 400 and new


def test_a_new_face_is_taken_at_once_when_the_followed_one_vanishes() -> None:
    """Nobody else was in view: holding would only publish nothing (the person
    stepped in faster than the track could follow, or someone else arrived)."""
    tr = TargetTracker(switch_after_s=0.5)
    tr.select([face(130, 120, 90)], 0.0)
    chosen, new = tr.select([face(470, 330, 150)], 0.033)
    assert chosen is not None and chosen.centre == (470, 330) and new
    assert tr.target_changes == 2


def test_a_bystander_is_held_back_but_a_newcomer_next_to_them_is_not() -> None:
    tr = TargetTracker(switch_after_s=0.5)
    tr.select([face(100, 100, 100), face(400, 100, 80)], 0.0)
    # The followed face is missed; the bystander moved a little: hold.
    assert tr.select([face(420, 100, 80)], 0.033) == (None, False)
    # A face where nobody was before, while the followed one is still missing: taken.
    chosen, new = tr.select([face(420, 100, 80), face(250, 350, 120)], 0.066)
    assert chosen is not None and chosen.centre == (250, 350) and new


def test_observe_confirms_without_changing_the_person() -> None:
    tr = TargetTracker(switch_after_s=0.5)
    tr.select([face(100, 100, 100)], 0.0)
    assert not tr.observe([face(400, 100, 150)], 0.1)  # someone else only
    assert tr.target_changes == 1
    assert tr.observe([face(400, 100, 150), face(104, 100, 100)], 0.2)
    # The other face is now a known bystander: a missed frame does not switch to it.
    assert tr.select([face(400, 100, 150)], 0.233) == (None, False)


def test_follow_moves_the_track_for_the_next_match() -> None:
    tr = TargetTracker()
    tr.select([face(100, 100, 100)], 0.0)
    for i in range(1, 10):
        tr.follow(face(100 + 40 * i, 100, 100), i / 30)  # crop results, 0.4 widths a frame
    chosen, new = tr.select([face(480, 100, 100)], 0.4)
    assert chosen is not None and not new and tr.target_changes == 1


def test_a_face_back_after_forget_after_s_is_a_new_person() -> None:
    """Same place, but the room was empty for longer than `forget_after_s`: new person
    (the pipeline then restarts smoothing and forgets the iris it learnt)."""
    tr = TargetTracker(forget_after_s=3.0)
    here = face(100, 100, 60)
    assert tr.select([here], 0.0) == (here, True)
    assert tr.select([here], 1.0) == (here, False)  # seen again soon: the same person
    assert tr.select([], 2.0) == (None, False)
    assert tr.select([here], 3.9) == (here, False)  # 2.9 s unseen: still them
    assert tr.select([], 5.0) == (None, False)
    assert tr.select([here], 7.5) == (here, True)  # 3.6 s unseen: somebody new
