"""Report frame -> contract message, clamping or emptying what the contract forbids.

Pure (msgspec types only). The contract declares energies 0..100 and a
subscriber drops a message that breaks it; real LD2410s occasionally
report an energy above 100, so the value is clamped to 100 and counted
here rather than published as a message every subscriber would refuse.

The two bytes after the gate energies are light level and OUT pin only
on firmware V2.x; V1.07 sends two other bytes there (a real module's
"OUT pin" read 33). So they are published only when the caller knows the
firmware has them, and an OUT pin that is neither 0 nor 1 is published
as None and counted: a wrong value is worse than no value.
"""

from __future__ import annotations

from typing import NamedTuple

from buddybot.contract import messages as m
from buddybot.radar.ld2410 import Report

ENERGY_MAX = 100


class Converted(NamedTuple):
    """The message, how many energies were clamped, whether an OUT pin was refused."""

    frame: m.LD2410TargetDataFrame
    clamped: int
    bad_out_pin: bool


def _clamp(values: tuple[int, ...] | None) -> tuple[list[int] | None, int]:
    if values is None:
        return None, 0
    over = sum(1 for v in values if v > ENERGY_MAX)
    return [min(v, ENERGY_MAX) for v in values], over


def report_to_frame(report: Report, radar_id: int, light_and_out: bool = False) -> Converted:
    """The message for one report; `light_and_out`: the firmware defines the last two
    bytes of an engineering report as light level and OUT pin (V2.x)."""
    moving_gates, over_m = _clamp(report.moving_gate_energy)
    still_gates, over_s = _clamp(report.still_gate_energy)
    clamped = over_m + over_s
    clamped += (report.moving_energy > ENERGY_MAX) + (report.still_energy > ENERGY_MAX)
    light = out = None
    bad_out = False
    if light_and_out:
        light = report.light_level
        out = report.out_pin
        if out is not None and out not in (0, 1):
            out, bad_out = None, True
    frame = m.LD2410TargetDataFrame(
        radar_id=radar_id,
        target_state=m.TargetState(report.target_state),
        movement_distance=report.moving_distance,
        movement_energy=min(report.moving_energy, ENERGY_MAX),
        stationary_distance=report.still_distance,
        stationary_energy=min(report.still_energy, ENERGY_MAX),
        detection_distance=report.detection_distance,
        max_moving_gate=report.max_moving_gate,
        max_stationary_gate=report.max_still_gate,
        moving_gate_energy=moving_gates,
        stationary_gate_energy=still_gates,
        light_level=light,
        out_pin=out,
    )
    return Converted(frame, int(clamped), bad_out)
