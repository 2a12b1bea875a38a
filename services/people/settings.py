"""Config table `[people]` (pure msgspec struct).

Zone limits follow Hall's proxemics (the far edge of each zone, metres);
timings are seconds; the angle radars' tracker and the face fusion have
their own fields. The reason for each default is next to it. Every field but
`camera` and `tick_s` is live (`buddybot param set people ...`): the model
reads its settings on every input and tick. `camera` and `tick_s` are read
once at start.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

Limit = Annotated[float, msgspec.Meta(
    gt=0.0, le=20.0, description="metres: far edge of a zone (a room is within 20 m)",
    extra={"live": True})]
Timeout = Annotated[float, msgspec.Meta(gt=0.0, le=60.0, extra={"live": True})]
"""Seconds, live: how long an angle-radar sighting counts."""
Hold = Annotated[float, msgspec.Meta(
    ge=0.0, le=3600.0, description="seconds: how long a condition must last (0: at once)",
    extra={"live": True})]


class PeopleSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[people]`: the camera followed, zones (with hysteresis), and the timings of
    presence and engagement."""

    # The controller's default camera: both follow the same face.
    camera: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64, description="camera whose followed face is read")
    ] = "front"
    # Hall's intimate zone ends at 45 cm (18 in): closer is touching distance.
    intimate_limit_m: Annotated[Limit, msgspec.Meta(examples=[0.4])] = 0.45
    # Hall's personal zone ends at 1.2 m (4 ft): a conversation with a friend.
    personal_limit_m: Annotated[Limit, msgspec.Meta(examples=[1.5])] = 1.2
    # Hall's social zone ends at 3.6 m (12 ft): beyond it nobody is talking to the robot.
    social_limit_m: Annotated[Limit, msgspec.Meta(examples=[4.0])] = 3.6
    # Above the face distance's wobble (~0.1 m at the social limit), a third of the intimate zone.
    zone_margin_m: Annotated[float, msgspec.Meta(
        ge=0.0, le=2.0, description="metres: a zone is left only this far past its limit",
        extra={"live": True})] = 0.15
    # Several frames at any usable camera rate: a missed detection does not lose the face.
    face_timeout_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0,
        description="seconds: a face older than this no longer counts as seen",
        extra={"live": True})] = 0.5
    # A glance in passing lasts under a second (the controller greets after as long).
    engage_dwell_s: Hold = 1.0
    # A face missed for a moment (a blink of the detector, a nod) is not looking away.
    look_away_s: Hold = 1.0
    # A look at a phone or a step back for a moment keeps the engagement.
    disengage_hold_s: Hold = 2.0
    # The one time from leaving to LEFT (the controller's farewell follows it), counted
    # from the sensors' last sighting; as long as radar presence's own absence hold,
    # which it overlaps, so a visitor is still within earshot of the goodbye.
    absence_hold_s: Annotated[Hold, msgspec.Meta(
        description="seconds: seen by no sensor this long after their last sighting, a "
        "person has left (the one time from leaving to LEFT)")] = 3.0
    # A fan or a curtain never shows a face and never walks through the room; a person
    # shown only by the radar, standing still from the moment they appeared, is taken
    # for one after this long (a face brings a person back at once).
    clutter_after_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0, description="seconds: a person only the radar has shown, never "
        "more than `clutter_spread_m` from where it first did, is clutter after this long",
        extra={"live": True})] = 20.0
    # An LD2410 measures in gates of 0.75 m: a fan may hop one; a person walking in
    # moves further.
    clutter_spread_m: Annotated[float, msgspec.Meta(
        ge=0.0, le=5.0, description="metres: a radar target that stays within this of "
        "where it first appeared has not moved through the room", extra={"live": True})
    ] = 0.8
    # Angle radars (LD2450): a brisk walk moves 0.15 m between two reports (10/s) and
    # a target jitters by ~0.1 m; two people side by side stand ~0.6 m apart.
    track_gate_m: Annotated[float, msgspec.Meta(
        gt=0.0, le=5.0, description="metres: a target this near a track's predicted "
        "position continues it", extra={"live": True})] = 0.6
    # A missed report or two, or a person hidden behind another for a moment, keeps the id.
    track_coast_s: Annotated[Timeout, msgspec.Meta(
        description="seconds: a track no report matched this long is dropped")] = 1.0
    # Three targets per LD2450, a few sensors: 8 is more than a desk robot meets at once.
    max_tracks: Annotated[int, msgspec.Meta(
        ge=1, le=64, description="most radar tracks (persons) at once",
        extra={"live": True})] = 8
    # A face's bearing and the radar's agree within a few degrees when both are placed
    # right; 10 degrees also absorbs a mounting pose measured by eye.
    fusion_angle_deg: Annotated[float, msgspec.Meta(
        ge=0.0, le=90.0, description="degrees: a face this near a track's bearing is that "
        "person's", extra={"live": True})] = 10.0
    # The face's distance comes from its size (+-20 %): 1 m covers it at 3-4 m.
    fusion_distance_m: Annotated[float, msgspec.Meta(
        ge=0.0, le=20.0, description="metres: ... and this near its distance",
        extra={"live": True})] = 1.0
    # An LD2450 reports 10 times a second, also with nobody in view.
    radar_timeout_s: Annotated[Timeout, msgspec.Meta(
        description="seconds: angle radars count as reporting this long after a report "
        "(then radar/presence makes the person again)")] = 1.0
    # An LD2450 reports 10 times a second: as many positions keep a map or a radar-led
    # gaze smooth and spare every reader the camera's 30 (news never waits).
    position_period_s: Annotated[float, msgspec.Meta(
        ge=0.0, le=1.0, description="seconds: a change only in where people are (distance, "
        "direction) goes out on people/state at most this often (0: every change)",
        extra={"live": True})] = 0.1
    # Timers fire within a tick of their deadline: 50 ms is below what a person notices.
    tick_s: Annotated[float, msgspec.Meta(
        ge=0.005, le=1.0, description="seconds: period of the timers (ticks)")] = 0.05

    def __post_init__(self) -> None:
        if not self.intimate_limit_m < self.personal_limit_m < self.social_limit_m:
            raise ValueError("zone limits must grow: intimate_limit_m < personal_limit_m "
                             "< social_limit_m")
