"""Config table `[controller]` (pure msgspec structs).

Every timing of the social behaviour lives here with a default chosen for
the whole-robot demo (a visitor who comes, stays 20-30 s and leaves, a
face visible the whole time): greet once per visit after a short dwell,
say goodbye when they go. Setting every timing to 0 and `look_around`
to false gives the original ROS 2 design's behaviour exactly (eyes follow presence at
once, greeting as soon as radar and face agree). Negative timings are
refused when the file is read (the `ge=0` constraints).
"""

from __future__ import annotations

import math
from typing import Annotated

import msgspec

LIVE = {"live": True}
"""`msgspec.Meta(extra=LIVE)`: `buddybot param set controller ...` applies the field at
once (the behaviour reads its settings on every decision); unmarked fields are read
once at start and need a restart."""


def _s(description: str, *, positive: bool = False, live: bool = True) -> msgspec.Meta:
    """A timing's range (0..1 h, or >0 when 0 would never end) and its description;
    timings are live unless `live=False`."""
    extra = LIVE if live else None
    if positive:
        return msgspec.Meta(gt=0.0, le=3600.0, description=f"seconds: {description}",
                            extra=extra)
    return msgspec.Meta(ge=0.0, le=3600.0, description=f"seconds: {description}", extra=extra)


Metres = Annotated[float, msgspec.Meta(
    ge=-10.0, le=10.0, description="metres (a camera on the robot is well within 10 m)")]
Radians = Annotated[float, msgspec.Meta(
    ge=-math.tau, le=math.tau, description="radians, within one turn either way")]


class CameraToEyes(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Static transform: camera origin and orientation in the eyes-centre frame."""

    translation_m: tuple[Metres, Metres, Metres] = (0.0, 0.0, 0.0)
    """x, y, z of the camera in the eyes-centre frame, metres."""
    rpy_rad: tuple[Radians, Radians, Radians] = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw of the camera, radians."""


class ControllerSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[controller]`: which camera to follow, where it sits, and the behaviour's timings.

    Timings, all in seconds (why each default):

    * `farewell_delay_s` 0.0: the departure (and the farewell, if greeted)
      comes this long after the people service says the person left; how long
      a person nobody sees is held is the people service's `absence_hold_s`
      alone, so this adds no hold of its own by default.
    * `gaze_hold_s` 1.0: after the last face the eyes keep looking where it
      was (a blink, a turned head), then go to the radar's direction of the
      person or return to centre. Whether a face is seen at all is the people
      service's (`[people] face_timeout_s`): the controller has no timeout
      of its own.
    * `look_around_after_s` 2.0: someone is in range but no face for this
      long -> EYE_LOOK_RANDOM (searching); `look_around = false` disables it.
    * `greet_dwell_s` 1.0: in range with a face for this long before the
      greeting, so a passer-by is not greeted.
    * `regreet_cooldown_s` 6.0: coming back within this time after leaving
      is the same visit (no second greeting, no second farewell), and two
      greetings are never closer than this. Kept below the simulated
      radar's ~10 s between visits, so the demo greets every visitor.
    * `alone_s` 8.0: after the last person left, awake and alone this long
      (and while the farewell plays), looking around (EYE_LOOK_RANDOM),
      before drowsy: a robot that drops asleep the moment you turn reads as
      switched off.
    * `sleepy_s` 2.0: EYE_SLEEPY shown this long (and while the farewell
      plays, without `alone_s`) before EYE_SLEEP: asleep `alone_s` +
      `sleepy_s` after the last departure.
    * `farewell_max_delay_s` 5.0: a farewell that could not start within
      this time after the departure (device busy, cancel unconfirmed) is
      dropped: a goodbye to an empty room helps nobody.
    * `sound_timeout_s` 30.0: a goal with no final status after this long is
      taken as lost, so a dead audio service cannot block the robot forever.
    * `recover_s` 0.5: after start-up, and again after the first latched
      presence, listen this long to the latched topics (presence, expression,
      sound status, device free) before deciding, so a restart neither repeats
      an expression nor re-greets, even when the latched values come late.
    * `tick_s` 0.05: the decision loop's period for timers.

    Attention and motion (docs/controller.md, 'Attention'): a newcomer gets a
    glance of `glance_s`; another engaged person one every `share_every_s`;
    eye contact breaks for `aversion_s` by `aversion_deg` every
    `aversion_every_s`; walking faster than `linger_speed_mps` is passing
    (the greeting's dwell waits for them to slow down); a greeted visitor
    moving away at `leave_speed_mps`, `leave_distance_m` beyond the nearest
    they came, gets the farewell as they go. Anticipation: EYE_ALERT for
    `alert_s` when someone is noticed whose direction nobody knows (an
    LD2410 alone: nowhere to look, so the face reacts) or when the visit's
    person comes at `rush_speed_mps` or faster.
    """

    camera: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64, description="camera whose faces the eyes follow")] = "front"
    camera_to_eyes: CameraToEyes = msgspec.field(default_factory=CameraToEyes)
    greeting_sound: Annotated[str, msgspec.Meta(min_length=1, extra=LIVE)] = "greeting"
    greeting_named: Annotated[str, msgspec.Meta(
        max_length=256, extra=LIVE,
        description="sound for a visitor the people service names, `{name}` replaced by "
                    "the name (e.g. \"say:Hello {name}\"); empty: `greeting_sound`")] = ""
    greetings: Annotated[dict[Annotated[str, msgspec.Meta(min_length=1, max_length=64)],
                              Annotated[str, msgspec.Meta(min_length=1, max_length=256)]],
                         msgspec.Meta(max_length=10_000, extra=LIVE,
                                      description="per-person greeting: name -> sound "
                                                  "(before `greeting_named`)")] = msgspec.field(
        default_factory=dict)
    farewell_sound: Annotated[str, msgspec.Meta(min_length=1, extra=LIVE)] = "farewell"
    centre_distance_cm: Annotated[float, msgspec.Meta(
        ge=0.0, le=10000.0, extra=LIVE,
        description="cm: gaze distance sent when the eyes return to centre")] = 100.0
    look_around: Annotated[bool, msgspec.Meta(extra=LIVE)] = True
    farewell_delay_s: Annotated[float, _s("the departure (farewell if greeted) comes this "
                                          "long after the people service says the "
                                          "person left")] = 0.0
    gaze_hold_s: Annotated[float, _s("eyes keep looking where the last face was")] = 1.0
    look_around_after_s: Annotated[float, _s("in range with no face this long: search")] = 2.0
    greet_dwell_s: Annotated[float, _s("in range with a face this long before the "
                                       "greeting (no passer-by greeted)")] = 1.0
    regreet_cooldown_s: Annotated[float, _s("coming back within this is the same visit")] = 6.0
    alone_s: Annotated[float, _s("awake and alone, looking around, this long after the "
                                 "last person left, before drowsy")] = 8.0
    sleepy_s: Annotated[float, _s("EYE_SLEEPY shown this long before EYE_SLEEP")] = 2.0
    farewell_max_delay_s: Annotated[float, _s("a farewell not started within this after the "
                                              "departure is dropped")] = 5.0
    sound_timeout_s: Annotated[float, _s("a sound goal with no final status is lost after "
                                         "this (a dead audio service cannot block)",
                                         positive=True)] = 30.0
    recover_s: Annotated[float, _s("listen to latched topics this long after start, and "
                                   "after the first presence, before deciding (no repeated "
                                   "greeting)", live=False)] = 0.5
    tick_s: Annotated[float, msgspec.Meta(
        ge=0.005, le=1.0, description="seconds: period of the decision loop's timers")] = 0.05
    glance_s: Annotated[float, _s("a glance at a newcomer or another engaged person "
                                  "lasts this long")] = 1.2
    share_every_s: Annotated[float, _s("with another engaged person, a glance at them this "
                                       "often (0: never)")] = 4.0
    aversion_every_s: Annotated[float, _s("eye contact broken this often (0: never)")] = 3.0
    aversion_s: Annotated[float, _s("a gaze aversion lasts this long")] = 0.6
    aversion_deg: Annotated[float, msgspec.Meta(
        ge=0.0, le=30.0, extra=LIVE,
        description="degrees: how far a gaze aversion looks aside (0: never)")] = 7.0
    linger_speed_mps: Annotated[float, msgspec.Meta(
        gt=0.0, le=10.0, extra=LIVE,
        description="m/s: walking faster than this is passing by (no greeting yet)")] = 0.45
    leave_speed_mps: Annotated[float, msgspec.Meta(
        gt=0.0, le=10.0, extra=LIVE,
        description="m/s: a greeted visitor moving away this fast is leaving")] = 0.3
    leave_distance_m: Annotated[float, msgspec.Meta(
        ge=0.0, le=10.0, extra=LIVE,
        description="metres: a visitor moving away is leaving once this far beyond "
                    "the nearest they came")] = 0.3
    alert_s: Annotated[float, _s("EYE_ALERT this long for someone noticed without a "
                                 "direction or coming fast (0: never)")] = 1.5
    rush_speed_mps: Annotated[float, msgspec.Meta(
        gt=0.0, le=10.0, extra=LIVE,
        description="m/s: the visit's person coming nearer this fast is rushing in "
                    "(EYE_ALERT); slower is drifting near (EYE_AWAKE)")] = 1.0
    call_timeout_s: Annotated[float, _s("a service call (e.g. cancel) taking longer fails",
                                        positive=True, live=False)] = 3.0
