"""Report frame -> contract message, clamping or emptying what the contract forbids.

LD2410 reports become `LD2410TargetDataFrame`s; LD2450 reports become
`RadarTargets`, placed in the camera's frame by the sensor's mount.

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
from buddybot.radar import ld2450
from buddybot.radar.ld2410 import Report
from buddybot.radar.mounting import IDENTITY, Mount, place

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


class ConvertedTargets(NamedTuple):
    """The message, and how many of its targets lie outside the documented field."""

    message: m.RadarTargets
    implausible: int


def report_to_targets(report: ld2450.Report, device_id: int, radar_id: int, stamp_ns: int,
                      mount: Mount = IDENTITY) -> ConvertedTargets:
    """One LD2450 report -> `RadarTargets`, each target also placed in the camera's frame.

    A target beyond the sensor's documented field (x +-4000 mm, y 0..8000 mm)
    is still published (it is what the sensor said, and every value fits the
    contract) but counted, so diagnostics show a sensor reporting nonsense.
    """
    targets = []
    implausible = 0
    for slot, t in report.targets():
        implausible += not t.plausible()
        x_m, y_m = t.x_mm / 1000.0, t.y_mm / 1000.0
        placed = place(x_m, y_m, mount)
        targets.append(m.RadarTarget(
            slot=slot, x_m=x_m, y_m=y_m, speed_mps=t.speed_cms / 100.0,
            resolution_m=t.resolution_mm / 1000.0,
            position=m.Point(x=placed.x, y=placed.y, z=placed.z),
            bearing_rad=placed.bearing_rad, distance_m=placed.distance_m,
        ))
    message = m.RadarTargets(stamp_ns=stamp_ns, device_id=device_id, radar_id=radar_id,
                             targets=targets)
    return ConvertedTargets(message, implausible)
