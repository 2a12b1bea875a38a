"""LD2410 reports converted to the contract's frames: clamped, counted, decodable."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import ld2410 as p
from buddybot.radar.convert import report_to_frame


def test_energies_above_100_are_clamped_and_counted() -> None:
    report = p.Report(3, 120, 130, 140, 255, 125, engineering=True, max_moving_gate=8,
                      max_still_gate=8, moving_gate_energy=(101, *range(8)),
                      still_gate_energy=(*range(8), 200), light_level=80, out_pin=1)
    frame, clamped, _ = report_to_frame(report, 2)
    assert clamped == 4
    assert frame.movement_energy == 100 and frame.stationary_energy == 100
    assert frame.moving_gate_energy is not None and frame.moving_gate_energy[0] == 100
    assert frame.stationary_gate_energy is not None and frame.stationary_gate_energy[8] == 100
    assert (frame.radar_id, frame.movement_distance, frame.stationary_distance) == (2, 120, 140)
    msg = m.LD2410TargetDataFrameArray(stamp_ns=1, device_id=0, sensors=[frame])
    codec = keys.RADAR_FRAMES.codec
    assert codec.decode(codec.encode(msg), m.LD2410TargetDataFrameArray) == msg


def test_basic_report_has_no_engineering_fields() -> None:
    frame, clamped, _ = report_to_frame(p.Report(2, 0, 0, 300, 60, 300), 0)
    assert clamped == 0 and frame.target_state == m.TargetState.STATIONARY
    assert frame.moving_gate_energy is None and frame.light_level is None


def _engineering(light: int, out: int, state: int = 1) -> p.Report:
    return p.Report(state, 120, 50, 0, 0, 120, engineering=True, max_moving_gate=8,
                    max_still_gate=8, moving_gate_energy=(1,) * 9, still_gate_energy=(2,) * 9,
                    light_level=light, out_pin=out)


def test_light_and_out_only_from_firmware_that_has_them() -> None:
    """V1.07 sends two bytes there that are not light/OUT (a real module: OUT 33)."""
    v1 = report_to_frame(_engineering(120, 33), 0, light_and_out=False)
    assert (v1.frame.light_level, v1.frame.out_pin, v1.bad_out_pin) == (None, None, False)
    v2 = report_to_frame(_engineering(120, 1), 0, light_and_out=True)
    assert (v2.frame.light_level, v2.frame.out_pin, v2.bad_out_pin) == (120, 1, False)
    odd = report_to_frame(_engineering(120, 33), 0, light_and_out=True)
    assert (odd.frame.light_level, odd.frame.out_pin, odd.bad_out_pin) == (120, None, True)


@pytest.mark.parametrize("state", [4, 5, 6])
def test_noise_detection_states_convert_to_the_contract(state: int) -> None:
    frame = report_to_frame(p.Report(state, 0, 0, 0, 0, 0), 0).frame
    assert frame.target_state == m.TargetState(state)
    codec = keys.RADAR_FRAMES.codec
    msg = m.LD2410TargetDataFrameArray(stamp_ns=1, device_id=0, sensors=[frame])
    assert codec.decode(codec.encode(msg), m.LD2410TargetDataFrameArray) == msg


def test_out_of_contract_message_is_refused_at_decode() -> None:
    """Why we clamp: a subscriber would drop this message."""
    raw = b'{"stamp_ns":1,"device_id":0,"sensors":[{"radar_id":0,"target_state":1,' \
          b'"movement_distance":1,"movement_energy":101,"stationary_distance":0,' \
          b'"stationary_energy":0,"detection_distance":1}]}'
    with pytest.raises(msgspec.ValidationError):
        keys.RADAR_FRAMES.codec.decode(raw, m.LD2410TargetDataFrameArray)


def test_ld2450_report_to_targets_places_each_target_and_counts_implausible_ones() -> None:
    import math

    from buddybot.radar import ld2450
    from buddybot.radar.convert import report_to_targets
    from buddybot.radar.mounting import Mount

    report = ld2450.Report((None, ld2450.Target(-1000, 1000, -25, 320),
                            ld2450.Target(5000, 9000, 0, 360)))
    msg, implausible = report_to_targets(report, 2, 1, 123, Mount(z=0.5))
    assert (msg.device_id, msg.radar_id, msg.stamp_ns, msg.model) == (2, 1, 123, "LD2450")
    first, second = msg.targets
    assert (first.slot, first.x_m, first.y_m, first.speed_mps, first.resolution_m) == (
        1, -1.0, 1.0, -0.25, 0.32)
    assert (first.position.x, first.position.y, first.position.z) == (1.0, 1.0, 0.5)
    assert first.bearing_rad == math.atan2(1.0, 1.0) and first.distance_m == math.hypot(1, 1)
    assert second.slot == 2 and implausible == 1
    empty, none = report_to_targets(ld2450.Report((None, None, None)), 0, 0, 1)
    assert empty.targets == [] and none == 0
