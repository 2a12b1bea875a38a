"""Distance cue fusion (pure): weights by size, too-small and outlier cues, the record."""

from __future__ import annotations

import math

import pytest

from buddybot.camera import fusion as fu

FX = 600.0


def cues_at(z: float, iris_px: float | None = None) -> list[fu.Cue]:
    """Width, eye and (optionally) iris cues of a frontal average face at `z` metres."""
    out = [fu.width_cue(FX, 0.15, FX * 0.15 / z), fu.eye_cue(FX, 0.063, FX * 0.063 / z)]
    if iris_px is not None:
        out.append(fu.iris_cue(FX, iris_px))
    return out


def test_agreeing_cues_give_their_distance_and_weights_sum_to_one() -> None:
    f = fu.fuse(cues_at(0.5, FX * 0.0117 / 0.5))
    assert f is not None
    assert f.z_m == pytest.approx(0.5)
    assert sum(c.weight for c in f.cues) == pytest.approx(1.0)
    assert set(f.used) == {fu.WIDTH, fu.EYES, fu.IRIS}
    # The fused error is below the best single cue's.
    assert f.rel_sd < min(c.rel_sd for c in f.cues)


def test_the_iris_weight_grows_with_its_size_and_leads_close_up() -> None:
    weights = []
    for z in (1.0, 0.6, 0.3):
        f = fu.fuse(cues_at(z, FX * 0.0117 / z))
        assert f is not None
        weights.append(f.weight(fu.IRIS))
    assert weights[0] < weights[1] < weights[2]
    close = fu.fuse(cues_at(0.3, FX * 0.0117 / 0.3))
    assert close is not None and close.used[0] == fu.IRIS


def test_a_too_small_iris_is_ignored_whatever_it_says() -> None:
    without = fu.fuse(cues_at(1.5))
    f = fu.fuse([*cues_at(1.5), fu.iris_cue(FX, 4.0)])  # says 1.76 m
    assert f is not None and without is not None
    assert f.weight(fu.IRIS) == 0.0
    assert f.z_m == pytest.approx(without.z_m)
    assert fu.IRIS not in f.used
    assert f.as_dict()["dist_iris_w"] == fu.TOO_SMALL


def test_one_cue_far_from_the_others_is_dropped() -> None:
    # The iris model on closed eyes: a diameter half the right one (twice the distance).
    f = fu.fuse([*cues_at(0.4), fu.iris_cue(FX, FX * 0.0117 / 0.8)])
    assert f is not None
    assert [c.status for c in f.cues if c.name == fu.IRIS] == [fu.OUTLIER]
    assert f.z_m == pytest.approx(0.4)


def test_two_disagreeing_cues_are_both_kept() -> None:
    # With two cues there is no telling which is wrong: both stay, weighted.
    f = fu.fuse([fu.width_cue(FX, 0.15, 90.0), fu.eye_cue(FX, 0.063, 18.9)])
    assert f is not None
    assert set(f.used) == {fu.WIDTH, fu.EYES}
    assert 1.0 < f.z_m < 2.0


def test_a_small_agreement_error_is_averaged_not_dropped() -> None:
    f = fu.fuse([*cues_at(0.5), fu.iris_cue(FX, FX * 0.0117 / 0.53)])
    assert f is not None
    assert fu.IRIS in f.used
    assert 0.5 < f.z_m < 0.53


def test_the_eye_cue_is_corrected_for_yaw_and_refused_beyond_70_degrees() -> None:
    yaw = math.radians(40)
    c = fu.eye_cue(FX, 0.063, FX * 0.063 / 1.0 * math.cos(yaw), yaw)
    assert c.z_m == pytest.approx(1.0)
    assert c.rel_var > fu.eye_cue(FX, 0.063, 37.8).rel_var  # the correction costs trust
    turned = fu.eye_cue(FX, 0.063, 10.0, math.radians(75))
    assert turned.usable == fu.INVALID
    f = fu.fuse([fu.width_cue(FX, 0.15, 90.0), turned])
    assert f is not None and f.used == (fu.WIDTH,) and f.z_m == pytest.approx(1.0)


def test_nothing_usable_gives_none() -> None:
    assert fu.fuse([]) is None
    assert fu.fuse([fu.width_cue(FX, 0.15, 0.0), fu.iris_cue(FX, 2.0)]) is None


def test_the_record_for_the_debug_image_and_diagnostics() -> None:
    f = fu.fuse(cues_at(0.3, FX * 0.0117 / 0.3))
    assert f is not None
    text = f.summary()
    assert text.startswith("0.30 m iris ")
    assert "eyes" in text and "width" in text
    d = f.as_dict()
    assert d["dist_m"] == pytest.approx(0.3)
    assert d["dist_iris_m"] == pytest.approx(0.3)
    assert sum(float(d[f"dist_{n}_w"]) for n in (fu.WIDTH, fu.EYES, fu.IRIS)) == (
        pytest.approx(1.0, abs=0.01))


def test_calibration_turns_one_close_measurement_into_a_cue_at_any_distance() -> None:
    # A person with a 68 mm eye distance: the 63 mm eye cue says they are 7% nearer.
    cal = fu.IrisCalibration()
    assert cal.cue(FX, 40.0) is None
    z = 0.4
    assert cal.update(FX * 0.0117 / z, FX * 0.068 / z)
    assert cal.ipd_m == pytest.approx(0.068)
    for far in (0.8, 1.5, 2.5):
        eye_px = FX * 0.068 / far
        held = cal.cue(FX, eye_px)
        assert held is not None and held.name == fu.IRIS_HELD
        assert held.z_m == pytest.approx(far)
        assert fu.eye_cue(FX, 0.063, eye_px).z_m == pytest.approx(far * 0.063 / 0.068)
    # Facing 40 degrees away: the held cue is yaw-corrected like the eye cue.
    yaw = math.radians(40)
    held = cal.cue(FX, FX * 0.068 / 1.0 * math.cos(yaw), yaw)
    assert held is not None and held.z_m == pytest.approx(1.0)


def test_calibration_refuses_small_turned_impossible_and_outlying_measurements() -> None:
    cal = fu.IrisCalibration()
    assert not cal.update(4.0, 20.0)  # iris too small to say anything
    assert not cal.update(20.0, 100.0, math.radians(40))  # turned: the ratio is unsure
    assert not cal.update(20.0, 60.0)  # 35 mm between the pupils: no adult
    assert cal.measurements == 0 and cal.ipd_m is None
    assert cal.update(17.55, 94.5)  # 63 mm
    assert not cal.update(17.55 * 0.8, 94.5)  # one eye closed: 20% off, rejected
    assert cal.update(17.55 * 1.01, 94.5)
    assert cal.measurements == 2 and cal.rejected == 2
    assert cal.ipd_m == pytest.approx(0.063, rel=0.01)
    cal.reset()
    assert cal.ipd_m is None and cal.cue(FX, 40.0) is None


def test_the_held_cue_is_fused_like_any_other() -> None:
    cal = fu.IrisCalibration()
    assert cal.update(FX * 0.0117 / 0.4, FX * 0.063 / 0.4)
    one = cal.cue(FX, FX * 0.063 / 1.2)
    for _ in range(3):  # two seconds of a person at 0.4 m: a few measurements
        assert cal.update(FX * 0.0117 / 0.4, FX * 0.063 / 0.4)
    held = cal.cue(FX, FX * 0.063 / 1.2)
    assert one is not None and held is not None
    assert held.rel_var < one.rel_var
    f = fu.fuse([*cues_at(1.2), held])
    assert f is not None and f.z_m == pytest.approx(1.2)
    # Once measured a few times it leads: smaller prior than the eyes, same pixels.
    assert f.used[0] == fu.IRIS_HELD
