"""Report frame -> contract message, clamping what the contract forbids.

Pure (msgspec types only). The contract declares energies 0..100 and a
subscriber drops a message that breaks it; real LD2410s occasionally
report an energy above 100, so the value is clamped to 100 and counted
here rather than published as a message every subscriber would refuse.
"""

from __future__ import annotations

from buddybot.core import messages as m
from buddybot.radar.ld2410 import Report

ENERGY_MAX = 100


def _clamp(values: tuple[int, ...] | None) -> tuple[list[int] | None, int]:
    if values is None:
        return None, 0
    over = sum(1 for v in values if v > ENERGY_MAX)
    return [min(v, ENERGY_MAX) for v in values], over


def report_to_frame(report: Report, radar_id: int) -> tuple[m.LD2410TargetDataFrame, int]:
    """The message for one report, and how many energy values had to be clamped."""
    moving_gates, over_m = _clamp(report.moving_gate_energy)
    still_gates, over_s = _clamp(report.still_gate_energy)
    clamped = over_m + over_s
    clamped += (report.moving_energy > ENERGY_MAX) + (report.still_energy > ENERGY_MAX)
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
        light_level=report.light_level,
        out_pin=report.out_pin,
    )
    return frame, int(clamped)
