"""The message contract (docs/design.md section 3), as msgspec types.

These structs are the single source of truth: the key catalogue
(`keys.py`) binds them to key expressions, `schemas/` is generated from
them, and the CLI validates user input against them. Field names and
units are the contract; ranges are declared with `msgspec.Meta` so a
value out of range is rejected when a message is *decoded*, wherever it
came from.

`stamp_ns` is the time (ns since the Unix epoch) of the *sensor data* a
message derives from, so latency can be traced end to end; a message
that is not derived from sensor data (a request, a status) uses its own
creation time.
"""

from __future__ import annotations

import enum
import time
from typing import Annotated, Any, Literal

import msgspec

# --- reusable constrained scalar types -------------------------------------

StampNs = Annotated[int, msgspec.Meta(ge=0, description="ns since the Unix epoch")]
Centimetres = Annotated[int, msgspec.Meta(ge=0, le=65535, description="cm, 16-bit")]
Energy = Annotated[int, msgspec.Meta(ge=0, le=100, description="LD2410 energy 0..100")]
Percent = Annotated[float, msgspec.Meta(ge=0.0, le=100.0)]
Unit = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Metres = Annotated[float, msgspec.Meta(ge=0.0, le=1000.0, description="m, finite")]
Coordinate = Annotated[float, msgspec.Meta(ge=-1000.0, le=1000.0, description="m, finite")]
DistanceCm = Annotated[float, msgspec.Meta(ge=0.0, le=100000.0, description="cm, finite")]
Gate = Annotated[int, msgspec.Meta(ge=0, le=8)]
FrameId = Annotated[str, msgspec.Meta(max_length=256, description="camera frame name")]
GoalId = Annotated[str, msgspec.Meta(max_length=64)]
Text = Annotated[str, msgspec.Meta(max_length=4096, description="human-readable text")]
Byte = Annotated[int, msgspec.Meta(ge=0, le=255)]


def now_ns() -> int:
    """Wall-clock time in ns since the epoch, the unit of every `stamp_ns`."""
    return time.time_ns()


class Message(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """Base of every message: unknown fields are refused so a typo such as
    `rader_id` (the original ROS 2 spelling) is an error, never a silently missing value."""


# --- radar -----------------------------------------------------------------


class TargetState(enum.IntEnum):
    """LD2410 target state byte: bit 0 moving, bit 1 stationary.

    Values 4-6 are sent by LD2410C firmware while it measures the room's
    background noise (auto thresholds): no target information then.
    """

    NO_TARGET = 0
    MOVING = 1
    STATIONARY = 2
    MOVING_AND_STATIONARY = 3
    NOISE_DETECTING = 4
    NOISE_DETECTION_SUCCEEDED = 5
    NOISE_DETECTION_FAILED = 6


TARGET_STATES = (TargetState.MOVING, TargetState.STATIONARY, TargetState.MOVING_AND_STATIONARY)
"""The states that carry a target; NO_TARGET and the noise states carry none."""


def target_distance_cm(state: int, detection_cm: int, moving_cm: int, still_cm: int) -> int:
    """The distance of an LD2410 target, in cm, as every reader takes it: the
    detection distance, or, when a module says "target" with 0 cm there (seen
    on real modules), the distance of the kind it reports (moving first); 0
    when the state carries no target."""
    if state not in TARGET_STATES:
        return 0
    if detection_cm:
        return detection_cm
    return moving_cm if state & TargetState.MOVING else still_cm


class LD2410TargetDataFrame(Message):
    """One LD2410 report frame, as the sensor sent it (distances in cm)."""

    radar_id: Annotated[int, msgspec.Meta(ge=0)]
    target_state: TargetState
    movement_distance: Centimetres
    movement_energy: Energy
    stationary_distance: Centimetres
    stationary_energy: Energy
    detection_distance: Centimetres
    # Engineering mode only (None in basic mode).
    max_moving_gate: Gate | None = None
    max_stationary_gate: Gate | None = None
    moving_gate_energy: list[Energy] | None = None
    stationary_gate_energy: list[Energy] | None = None
    light_level: Byte | None = None
    out_pin: Byte | None = None


class LD2410TargetDataFrameArray(Message):
    """Frames of one radar bridge (`device_id`), one entry per sensor."""

    stamp_ns: StampNs
    device_id: Annotated[int, msgspec.Meta(ge=0)]
    sensors: list[LD2410TargetDataFrame]


SensorMetres = Annotated[float, msgspec.Meta(
    ge=-32.768, le=32.768, description="m, the sensor's own axes (16-bit mm)")]
MAX_RADAR_TARGETS = 8
"""Most targets one angle-radar report carries (the LD2450 tracks 3)."""


class RadarTarget(Message):
    """One target of an angle radar (LD2450) report.

    `x_m`/`y_m` are the sensor's own axes as its datasheet defines them (y
    away from the sensor's face, x across it), decoded from sign-magnitude;
    `position` is the same point in the camera's frame (ROS axes: x forward,
    y left, z up, like `FacePosition.point`), placed by the sensor's
    mounting pose, and `bearing_rad`/`distance_m` are its direction and
    horizontal range seen from the camera.
    """

    slot: Annotated[int, msgspec.Meta(ge=0, lt=MAX_RADAR_TARGETS,
                                      description="the sensor's slot (it may swap)")]
    x_m: SensorMetres
    y_m: SensorMetres
    speed_mps: Annotated[float, msgspec.Meta(ge=-327.68, le=327.68,
                                             description="m/s, + = moving away")]
    resolution_m: Annotated[float, msgspec.Meta(ge=0.0, le=65.535, description="m")]
    position: Point
    bearing_rad: Annotated[float, msgspec.Meta(ge=-3.15, le=3.15,
                                               description="rad, + = the robot's left")]
    distance_m: Metres


class RadarTargets(Message):
    """Every report of one angle radar: its targets now (empty: nobody)."""

    stamp_ns: StampNs
    """When the report was read."""
    device_id: Annotated[int, msgspec.Meta(ge=0)]
    radar_id: Annotated[int, msgspec.Meta(ge=0, description="the sensor's index in the bridge")]
    model: Literal["LD2450"] = "LD2450"
    targets: Annotated[list[RadarTarget], msgspec.Meta(max_length=MAX_RADAR_TARGETS)] = (
        msgspec.field(default_factory=list))


class PresenceTarget(enum.IntEnum):
    MOVING = 0
    STANDING = 1


class PresenceState(enum.IntEnum):
    OUT_OF_RANGE = 0
    IN_RANGE = 1


class PresenceDetection(Message):
    """Radar presence verdict, published on change and latched."""

    stamp_ns: StampNs
    target_state: PresenceTarget
    presence_state: PresenceState
    distance_m: Metres


# --- camera ----------------------------------------------------------------

MAX_SIDE = 16384
"""Largest width or height of an image the messages carry: a larger frame is
refused as malformed by every subscriber, so the camera refuses it first."""


class Image(Message):
    """A camera frame. `bgr8`: raw rows of BGR bytes; `jpeg`: a JPEG file.
    Always MessagePack on the wire (JSON would cost 40x more)."""

    stamp_ns: StampNs
    frame_id: FrameId
    width: Annotated[int, msgspec.Meta(gt=0, le=MAX_SIDE)]
    height: Annotated[int, msgspec.Meta(gt=0, le=MAX_SIDE)]
    encoding: Literal["bgr8", "jpeg"]
    data: bytes


class Point(Message):
    """A 3-D point in metres (ROS axes: x forward, y left, z up)."""

    x: Coordinate
    y: Coordinate
    z: Coordinate


FaceTrack = Annotated[int, msgspec.Meta(
    ge=1, description="the face detector's id of the person it follows: a new one whenever "
                      "it follows another person, never reused (also across restarts)")]


class FacePosition(Message):
    """The tracked face centre relative to the camera, in metres."""

    stamp_ns: StampNs
    frame_id: FrameId
    point: Point
    confidence: Unit
    track: FaceTrack | None = None
    """Whose face this is, as the detector follows them (None: a source without ids):
    a name given to one track never belongs to the next."""


Pixel = Annotated[float, msgspec.Meta(ge=-100000.0, le=100000.0, description="image pixels")]


class PixelPoint(Message):
    """A point in image pixels (x right, y down, origin at the top-left corner)."""

    x: Pixel
    y: Pixel


class FaceBox(Message):
    """One detected face, in the pixels of the image it was found in.

    `keypoints` are BlazeFace's six, in its order: the subject's right eye,
    left eye, nose tip, mouth centre, right ear, left ear.
    """

    x0: Pixel
    y0: Pixel
    x1: Pixel
    y1: Pixel
    score: Unit
    keypoints: Annotated[list[PixelPoint], msgspec.Meta(max_length=6)] = msgspec.field(
        default_factory=list)
    followed: bool = False
    """The face the robot follows (the one `camera/<cam>/face` is about)."""


class DistanceCue(Message):
    """One distance cue of the followed face and its part in the fused distance."""

    name: Annotated[str, msgspec.Meta(max_length=32, description="width, eyes, iris, ...")]
    distance_m: Metres | None
    """None when the cue gave no finite distance."""
    weight: Unit
    status: Annotated[str, msgspec.Meta(max_length=64, description="'used' or why not")]


class FaceDetections(Message):
    """Every face of one processed frame, so a viewer draws boxes itself.

    Published for every processed frame, also when no face was found (an
    empty list), so a viewer clears its boxes.
    """

    stamp_ns: StampNs
    frame_id: FrameId
    width: Annotated[int, msgspec.Meta(gt=0, le=MAX_SIDE, description="image width, px")]
    height: Annotated[int, msgspec.Meta(gt=0, le=MAX_SIDE, description="image height, px")]
    faces: Annotated[list[FaceBox], msgspec.Meta(max_length=64)] = msgspec.field(
        default_factory=list)
    tracked: bool = False
    """The followed face was re-found in its crop (no whole-frame pass this frame)."""
    track: FaceTrack | None = None
    """The followed face's track, as on `camera/{camera}/face` (None: no followed face)."""
    distance_m: Metres | None = None
    """The followed face's fused distance (before smoothing), None without one."""
    cues: Annotated[list[DistanceCue], msgspec.Meta(max_length=8)] = msgspec.field(
        default_factory=list)


# --- eyes ------------------------------------------------------------------


class ExpressionAction(enum.IntEnum):
    EYE_AWAKE = 0
    EYE_SLEEP = 1
    EYE_SLEEPY = 2
    EYE_GRIN = 3
    EYE_SAD = 4
    EYE_LOOK_RANDOM = 5
    ANIMATE_LOVE = 6
    ANIMATE_STAR = 7
    EYE_ALERT = 8
    """Wide open: someone appeared or came fast (the radar's anticipation)."""


class ScreenExpression(Message):
    stamp_ns: StampNs
    action: ExpressionAction


class EyeControl(Message):
    """Gaze target in the eyes-centre frame: radians (+yaw left, +pitch up)."""

    stamp_ns: StampNs
    yaw: Annotated[float, msgspec.Meta(ge=-3.15, le=3.15)]
    pitch: Annotated[float, msgspec.Meta(ge=-1.58, le=1.58)]
    target_distance_cm: DistanceCm


class EyesDirection(Message):
    """Gaze for the renderer, degrees (+yaw left, +pitch up).

    `target_distance_cm` is how far the looked-at person is, so the pages
    can converge the eyes as they come closer; None when unknown (the
    controller's "0 = unknown" of `EyeControl`, or an older sender).
    """

    stamp_ns: StampNs
    yaw: Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
    pitch: Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
    target_distance_cm: DistanceCm | None = None


class PupilControl(Message):
    stamp_ns: StampNs
    dilation_percentage: Percent


class EyeId(enum.IntEnum):
    LEFT = 0
    RIGHT = 1
    BOTH = 2


class EyeLidControl(Message):
    """Lid positions: 0/0 fully open, 50/50 closed (the lids meet)."""

    stamp_ns: StampNs
    eye_id: EyeId
    top_lid_position: Percent
    bottom_lid_position: Percent


# --- audio -----------------------------------------------------------------


GoalState = Literal["ACCEPTED", "PLAYING", "SUCCEEDED", "CANCELED", "ABORTED"]
TERMINAL_GOAL_STATES: frozenset[str] = frozenset({"SUCCEEDED", "CANCELED", "ABORTED"})


TTS_PREFIX = "say:"
"""How a value of `[audio.sounds]` marks a text to speak instead of a file
(`hello = "say:Hello!"`), and how a `PlaySound` goal asks to speak a text
that no sound names (`PlaySound{sound: "say:Hello!"}`)."""
TTS_MAX_CHARS = 240
"""Longest text a goal may ask to speak (about 15 s of speech)."""


def spoken_text(sound: str) -> str | None:
    """The text a `say:<text>` goal asks to speak (surrounding spaces dropped);
    None for any other sound. ValueError with the reason when the text is
    empty, longer than TTS_MAX_CHARS or holds a non-printable character
    (a control character would reach espeak-ng and the logs)."""
    if not sound.startswith(TTS_PREFIX):
        return None
    text = sound[len(TTS_PREFIX):].strip()
    if not text:
        raise ValueError(f"nothing to say after {TTS_PREFIX!r}")
    if len(text) > TTS_MAX_CHARS:
        raise ValueError(f"text to say is {len(text)} characters long "
                         f"(at most {TTS_MAX_CHARS})")
    bad = next((c for c in text if not c.isprintable()), None)
    if bad is not None:
        raise ValueError(f"text to say holds a non-printable character {bad!r}")
    return text


FILE_PREFIX = "file:"
"""How a `PlaySound` goal (and a `PlayAudioFile` request) names a file of the
player's sound folders rather than a sound (`PlaySound{sound: "file:chime.wav"}`):
the player's sandbox alone decides whether it may be played."""
AUDIO_SUFFIXES = (".wav", ".flac", ".mp3", ".ogg", ".oga")
"""File suffixes the player decodes (WAV, FLAC, MP3, Ogg Vorbis)."""


def sound_file(sound: str) -> str | None:
    """The path a `file:<path>` goal asks to play (as given: relative to the
    player's sound folders, or absolute); None for any other sound. ValueError
    with the reason when the path is empty or holds a non-printable character
    (a NUL byte or a newline would reach the file system and the logs)."""
    if not sound.startswith(FILE_PREFIX):
        return None
    path = sound[len(FILE_PREFIX):]
    if not path.strip():
        raise ValueError(f"no file named after {FILE_PREFIX!r}")
    bad = next((c for c in path if not c.isprintable()), None)
    if bad is not None:
        raise ValueError(f"file name holds a non-printable character {bad!r}")
    return path


class PlaySound(Message):
    """Goal of the `audio/play_sound` action: a sound name from [audio.sounds],
    `say:<text>` to speak any text (1..TTS_MAX_CHARS printable characters), or
    `file:<path>` to play a file inside the player's sound folders."""

    sound: Annotated[str, msgspec.Meta(min_length=1, max_length=256)]


class PlaySoundReply(Message):
    goal_id: GoalId
    accepted: bool
    message: Text = ""


class PlaySoundStatus(Message):
    goal_id: GoalId
    state: GoalState
    progress: Unit = 0.0
    message: Text = ""
    stamp_ns: StampNs = 0


class CancelGoal(Message):
    goal_id: GoalId


class PlayAudioFile(Message):
    """Request to the player: a configured sound name, `say:<text>`, or a file
    inside its sound folders (`[audio_player] sound_dirs`), given as it is or
    as `file:<path>` (then never taken for a name); anything else is refused
    alike."""

    path: Annotated[str, msgspec.Meta(min_length=1, max_length=4096)]


class Trigger(Message):
    """Empty request (std_srvs/Trigger)."""


class TriggerReply(Message):
    success: bool
    message: Text = ""


class Bool(Message):
    stamp_ns: StampNs
    data: bool


# --- controller --------------------------------------------------------------

Resource = Literal["expression", "gaze", "audio"]
"""What a lease holds: the eyes' expression, their gaze, the speaker."""
EngagementPhase = Literal["idle", "noticed", "engaged", "leaving", "alone", "drowsy"]
Waiting = Literal["nothing", "face", "dwell", "cooldown", "sound_busy", "device_busy",
                  "recovery", "greeted", "yielded"]


class ControllerState(Message):
    """What the controller believes and why it waits: latched, published on change.

    `waiting` names what holds back the next sound: `face` (noticed, no
    face yet), `dwell` (face seen for less than the greeting dwell),
    `cooldown` (greeted less than `regreet_cooldown_s` ago), `sound_busy`
    (our own sound still playing), `device_busy` (`audio/device_free`
    false), `recovery` (listening to latched inputs after a start),
    `greeted` (this visit was greeted: nothing more until the farewell),
    `yielded` (a lease holds the speaker) or `nothing`. `waiting_s` is the
    time left when known (dwell, cooldown).
    """

    stamp_ns: StampNs
    phase: EngagementPhase
    expression: ExpressionAction | None = None
    in_range: bool = False
    face_visible: bool = False
    visit: Annotated[int, msgspec.Meta(ge=0, description="visits since start")] = 0
    person_id: PersonId | None = None
    """The people service's id of the person this visit is about (`people/state`)."""
    greeted: bool = False
    sound: Literal["greeting", "farewell", "unknown"] | None = None
    """The sound of ours playing now, if any."""
    farewell_pending: bool = False
    waiting: Waiting = "nothing"
    waiting_s: Annotated[float, msgspec.Meta(ge=0.0, le=86400.0, description="s")] = 0.0
    last_greeting_ns: StampNs | None = None
    last_farewell_ns: StampNs | None = None
    yielded: Annotated[list[Resource], msgspec.Meta(max_length=3)] = msgspec.field(
        default_factory=list)
    """The resources a lease holds now: the behaviour's own choice for them waits."""


# --- people ------------------------------------------------------------------

Zone = Literal["INTIMATE", "PERSONAL", "SOCIAL", "PUBLIC"]
"""Hall's proxemic zone, near to far (docs/people.md)."""
SeenBy = Literal["NONE", "RADAR", "CAMERA", "BOTH"]
"""Which sensors show a person now; NONE while missed but not yet gone."""
Engagement = Literal["NONE", "ENGAGING", "ENGAGED", "DISENGAGING", "GONE"]
PersonEventKind = Literal["ARRIVED", "ZONE_CHANGED", "ENGAGEMENT_CHANGED", "LEFT"]
PersonId = Annotated[int, msgspec.Meta(ge=1, description="visits since start, never reused")]
Yaw = Annotated[float, msgspec.Meta(ge=-3.15, le=3.15, description="rad, + = robot's left")]
Pitch = Annotated[float, msgspec.Meta(ge=-1.58, le=1.58, description="rad, + = up")]
MAX_PEOPLE = 64
"""Most persons one `PeopleState` carries (angle radars show several)."""


class Person(Message):
    """One person present, as the people service sees them now."""

    id: PersonId
    distance_m: Metres
    zone: Zone
    seen_by: SeenBy
    zone_since_ns: StampNs
    arrived_ns: StampNs
    engagement: Engagement
    engagement_since_ns: StampNs
    yaw_rad: Yaw | None = None
    pitch_rad: Pitch | None = None
    name: Annotated[str, msgspec.Meta(max_length=256)] | None = None
    bearing_rad: Yaw | None = None
    """The bearing of their angle-radar track now; None: no angle radar tracks them."""


class PeopleState(Message):
    """Every person present: latched, published on change."""

    stamp_ns: StampNs
    people: Annotated[list[Person], msgspec.Meta(max_length=MAX_PEOPLE)] = msgspec.field(
        default_factory=list)


class PersonEvent(Message):
    """Something happened to one person; `zone` and `engagement` are theirs after it."""

    stamp_ns: StampNs
    person_id: PersonId
    kind: PersonEventKind
    zone: Zone
    engagement: Engagement


# --- simulation --------------------------------------------------------------

MetresPerSecond = Annotated[float, msgspec.Meta(ge=-100.0, le=100.0, description="m/s")]


class SimPerson(Message):
    """One person of the simulated world as they really are (the truth to compare with)."""

    id: Annotated[int, msgspec.Meta(ge=1, description="the person's place in the scenario")]
    face: Annotated[str, msgspec.Meta(max_length=64)]
    position: Point
    """Their eyes, robot frame (m; z above the camera)."""
    vx_mps: MetresPerSecond
    vy_mps: MetresPerSecond
    facing_rad: Yaw
    """Where their face points (rad, 0 = the robot's forward, + = its left)."""
    distance_m: Metres
    bearing_rad: Yaw
    in_radar: bool
    """Inside the field of a presence radar at the camera (LD2410: 6 m, +-60 degrees)."""
    in_camera: bool
    """Their face is in the image, turned to the camera and not hidden by someone nearer."""
    name: Annotated[str, msgspec.Meta(max_length=64)] | None = None


class SimClutter(Message):
    """Something a radar sees that is not a person."""

    kind: Literal["fan", "ghost"]
    position: Point


class SimWorld(Message):
    """The simulated world now: who is really there, for tools, tests and the dashboard."""

    stamp_ns: StampNs
    scenario: Annotated[str, msgspec.Meta(max_length=256)]
    t_s: Annotated[float, msgspec.Meta(ge=0.0, description="scenario time, s")]
    lap: Annotated[int, msgspec.Meta(ge=0, description="how often a looping scenario restarted")]
    people: Annotated[list[SimPerson], msgspec.Meta(max_length=MAX_PEOPLE)] = msgspec.field(
        default_factory=list)
    clutter: Annotated[list[SimClutter], msgspec.Meta(max_length=MAX_PEOPLE)] = msgspec.field(
        default_factory=list)


# --- identity ----------------------------------------------------------------

PersonName = Annotated[str, msgspec.Meta(
    min_length=1, max_length=64, description="an enrolled person's name, 1-64 characters")]
"""The gallery's rule (`identity.gallery.valid_name`) also refuses control characters."""
Cosine = Annotated[float, msgspec.Meta(ge=-1.0, le=1.0, description="cosine similarity")]
MAX_KNOWN = 10_000
"""Most people one gallery holds (and one `KnownPeople` reply lists)."""


class FaceName(Message):
    """Who the followed face is, decided per face track by the identity service.

    Latched, published on change: when the track's vote settles on a name,
    when the followed face becomes another track or is lost, and at once when
    the name it carries is forgotten. `name` None: unknown, not yet decided,
    or no face followed (`track` None).
    """

    stamp_ns: StampNs
    frame_id: FrameId
    track: Annotated[int, msgspec.Meta(ge=1, description="face track, never reused")] | None = None
    name: PersonName | None = None
    score: Cosine | None = None
    """The best match's cosine of the frame that settled the vote."""
    votes: Annotated[int, msgspec.Meta(ge=0, le=1000)] = 0
    """Frames of this track that agreed on `name` (or were embedded, while unknown)."""


ENROL_MARGIN_S = 5.0
"""How much longer than its collection time an enrolment's answer may take: the
asker waits `timeout_s` + this, and the identity service drops a request older."""


class EnrolRequest(Message):
    """Remember the one face in front of the camera now under `name` (explicit consent)."""

    name: PersonName
    samples: Annotated[int, msgspec.Meta(ge=1, le=16, description="frames to embed")] = 5
    timeout_s: Annotated[float, msgspec.Meta(gt=0.0, le=60.0, description="s")] = 10.0
    replace: bool = False
    """An existing `name` is refused unless this is set; then its templates are replaced."""
    credential: Annotated[str, msgspec.Meta(max_length=256)] = ""
    """The robot's operator secret: a biometric change is an operator's act."""
    sent_ns: StampNs = 0
    """When the asker sent it (wall clock): a request its asker has given up on
    (`sent_ns` + `timeout_s` + ENROL_MARGIN_S ago) is dropped, and any forget
    after `sent_ns` wins over it (the face may be the one forgotten)."""


class EnrolReply(Message):
    success: bool
    message: Text = ""
    name: PersonName | None = None
    samples: Annotated[int, msgspec.Meta(ge=0, le=16)] = 0
    """Embeddings stored for `name`."""


class ForgetRequest(Message):
    """Erase one person's templates, or everybody's (`all`); exactly one of the two."""

    name: PersonName | None = None
    all: bool = False
    credential: Annotated[str, msgspec.Meta(max_length=256)] = ""
    """The robot's operator secret: a biometric change is an operator's act."""


class ForgetReply(Message):
    success: bool
    message: Text = ""
    forgotten: Annotated[list[PersonName], msgspec.Meta(max_length=MAX_KNOWN)] = msgspec.field(
        default_factory=list)


class KnownPerson(Message):
    """One enrolled person, without their templates (those never leave the identity service)."""

    name: PersonName
    enrolled_ns: StampNs
    last_seen_ns: StampNs | None = None
    samples: Annotated[int, msgspec.Meta(ge=0, le=16)] = 0


class KnownPeople(Message):
    """Everybody the gallery holds, by name (reply of `identity/list`)."""

    people: Annotated[list[KnownPerson], msgspec.Meta(max_length=MAX_KNOWN)] = msgspec.field(
        default_factory=list)
    retention_days: Annotated[float, msgspec.Meta(ge=0.0, le=36500.0)] | None = None
    """People not seen for this long are forgotten; None: kept until forgotten."""


# --- leases ------------------------------------------------------------------

LeasePriority = Literal["builtin", "app", "operator"]
"""Low to high. `builtin` is the controller's own behaviour (`controller/expression`,
`controller/eye_control`): it holds whatever no lease holds, and no request may ask for it."""
LEASE_PRIORITIES: tuple[str, ...] = ("builtin", "app", "operator")
LeaseId = Annotated[str, msgspec.Meta(max_length=64)]
"""A lease's public id (`L<n>-<run>`, what `leases/state` shows), or its
holder's handle `<public id>.<secret>` (what only the grant's reply carries,
and what commands and releases need)."""


def public_lease_id(given: str) -> str:
    """The public id of a lease id or of its holder's handle."""
    return given.partition(".")[0]


Credential = Annotated[str, msgspec.Meta(max_length=256)]
"""The robot's operator secret (`secrets/operator` in its state folder), or ""."""
NodeName = Annotated[str, msgspec.Meta(min_length=1, max_length=64,
                                       description="a node name: letters, digits, - and _")]
Resources = Annotated[list[Resource], msgspec.Meta(min_length=1, max_length=3)]
LeaseEndReason = Literal["released", "expired", "holder_gone", "preempted", "broken"]
MAX_LEASE_S = 86400.0
"""Longest lease duration the arbiter grants (a day); longer is refused."""
HOLDER_NOT_ALIVE = "holder not alive"
"""How the arbiter's refusal of a holder without a live liveliness token
begins: a program that just started retries on it (its token may not have
reached the arbiter yet), and on no other refusal."""


class LeaseRequest(Message):
    """`leases/acquire`: take `resources` from whoever holds them at a lower priority.

    `holder` and `instance` name the asking node's liveliness token
    (`nodes/<holder>/<instance>`): the lease ends when that token goes away
    (the program ended, crashed or was killed). `duration_s` None: until
    released; otherwise it expires on its own after that many seconds.
    Priority `operator` needs `credential`, the robot's operator secret.
    Ranges are checked by the arbiter, which refuses with the reason.
    """

    holder: NodeName
    instance: Annotated[str, msgspec.Meta(min_length=1, max_length=64,
                                          description="the holder's Zenoh session id")]
    resources: Resources
    priority: LeasePriority = "app"
    duration_s: float | None = None
    credential: Credential = ""


class LeaseReply(Message):
    granted: bool
    lease_id: LeaseId = ""
    """The holder's handle `<public id>.<secret>`: only this reply carries it."""
    message: Text = ""
    """Why it was refused, or which leases it took over."""
    expires_ns: StampNs | None = None


class LeaseRelease(Message):
    """`leases/release`: end a lease: its holder, with the handle (`released`),
    or an operator, with the public id and the operator `credential` (`broken`,
    recorded with `by`)."""

    lease_id: LeaseId
    reason: Text = ""
    by: NodeName | None = None
    """Who asks (recorded when an operator breaks a lease)."""
    credential: Credential = ""


class Lease(Message):
    lease_id: LeaseId
    holder: NodeName
    instance: Annotated[str, msgspec.Meta(max_length=64)]
    priority: LeasePriority
    resources: Resources
    granted_ns: StampNs
    expires_ns: StampNs | None = None


class LeaseEnd(Message):
    """Why a lease ended: `released`, `expired`, `holder_gone`, `preempted` or `broken`."""

    lease_id: LeaseId
    holder: NodeName
    reason: LeaseEndReason
    stamp_ns: StampNs
    message: Text = ""


class Leases(Message):
    """Every lease now (latched, on change), and the last ones that ended."""

    stamp_ns: StampNs
    leases: Annotated[list[Lease], msgspec.Meta(max_length=64)] = msgspec.field(
        default_factory=list)
    ended: Annotated[list[LeaseEnd], msgspec.Meta(max_length=16)] = msgspec.field(
        default_factory=list)


class EyesCommand(Message):
    """`eyes/command`: what a lease holder wants the eyes to do.

    The eyes driver publishes it on `eyes/expression` / `eyes/control` if
    `lease_id` holds `expression` (for `expression`) and `gaze` (for the
    gaze fields); it is the one publisher of both keys, so `eyes/expression`
    keeps exactly one retained value whoever drives it. `pupil_percent`
    (needs `gaze`) sets the pupils' dilation instead of the one the driver's
    curve gives for the distance, until the next gaze.
    """

    lease_id: LeaseId
    expression: ExpressionAction | None = None
    yaw: Annotated[float, msgspec.Meta(ge=-3.15, le=3.15)] | None = None
    pitch: Annotated[float, msgspec.Meta(ge=-1.58, le=1.58)] | None = None
    target_distance_cm: DistanceCm = 0.0
    pupil_percent: Percent | None = None


# --- system ----------------------------------------------------------------


DiagnosticLevel = Literal["OK", "WARN", "ERROR"]
DiagnosticValue = str | int | float | bool


class DiagnosticStatus(Message):
    """Health of one node: published periodically and on every change."""

    stamp_ns: StampNs
    node: Annotated[str, msgspec.Meta(max_length=64)]
    level: DiagnosticLevel
    message: Text
    values: Annotated[dict[str, DiagnosticValue], msgspec.Meta(max_length=256)] = msgspec.field(
        default_factory=dict)


class ErrorReply(Message):
    """Body of a query's error reply: what was wrong with the request."""

    error: Text



# --- parameters and introspection (`buddybot param`, `buddybot node info`) ---

ParamName = Annotated[str, msgspec.Meta(max_length=256, description="a settings field")]
KeyText = Annotated[str, msgspec.Meta(max_length=1024, description="a key expression")]


class ParamRequest(Message):
    """A request to a node's `params/<node>` service.

    `list`: every field; `get`: the field `name`; `set`: apply `values`
    (one field for `param set`, a whole table for `param load`) at once and
    all together: one refused value refuses the whole request. Values are
    plain JSON; the node validates them against its own settings type.
    """

    op: Literal["list", "get", "set"]
    name: ParamName = ""
    values: Annotated[dict[ParamName, Any], msgspec.Meta(max_length=256)] = msgspec.field(
        default_factory=dict)


class ParamInfo(Message):
    """One settings field as the node holds it now."""

    name: ParamName
    value: Any
    type: Annotated[str, msgspec.Meta(max_length=256, description="Python annotation")]
    range: Annotated[str, msgspec.Meta(max_length=256, description="allowed values, words")]
    live: bool
    """True: a change applies at once; False: the node must restart (a set is refused)."""
    description: Text = ""


class ParamReply(Message):
    """The node's table after the request (`params`: the fields asked for).

    `error` is empty on success; else the request was refused as a whole
    (`unknown`: it named a field the table does not have: a usage error).
    """

    node: Annotated[str, msgspec.Meta(max_length=64)]
    table: Annotated[str, msgspec.Meta(max_length=64, description="the config table")]
    params: Annotated[list[ParamInfo], msgspec.Meta(max_length=256)] = msgspec.field(
        default_factory=list)
    changed: Annotated[list[ParamName], msgspec.Meta(max_length=256)] = msgspec.field(
        default_factory=list)
    error: Text = ""
    unknown: bool = False


class NodeInfo(Message):
    """What a node declared on the bus, as it reports it itself (keys relative
    to `buddybot/<robot>/`, wildcards as declared)."""

    node: Annotated[str, msgspec.Meta(max_length=64)]
    instance: Annotated[str, msgspec.Meta(max_length=64, description="Zenoh session id")]
    publishers: Annotated[list[KeyText], msgspec.Meta(max_length=1024)] = msgspec.field(
        default_factory=list)
    subscriptions: Annotated[list[KeyText], msgspec.Meta(max_length=1024)] = msgspec.field(
        default_factory=list)
    services: Annotated[list[KeyText], msgspec.Meta(max_length=1024)] = msgspec.field(
        default_factory=list)


ALL_MESSAGES: tuple[type[Message], ...] = (
    LD2410TargetDataFrame,
    LD2410TargetDataFrameArray,
    RadarTarget,
    RadarTargets,
    PresenceDetection,
    Image,
    Point,
    FacePosition,
    PixelPoint,
    FaceBox,
    DistanceCue,
    FaceDetections,
    ScreenExpression,
    EyeControl,
    EyesDirection,
    PupilControl,
    EyeLidControl,
    ControllerState,
    Person,
    PeopleState,
    PersonEvent,
    SimPerson,
    SimClutter,
    SimWorld,
    FaceName,
    EnrolRequest,
    EnrolReply,
    ForgetRequest,
    ForgetReply,
    KnownPerson,
    KnownPeople,
    LeaseRequest,
    LeaseReply,
    LeaseRelease,
    Lease,
    LeaseEnd,
    Leases,
    EyesCommand,
    PlaySound,
    PlaySoundReply,
    PlaySoundStatus,
    CancelGoal,
    PlayAudioFile,
    Trigger,
    TriggerReply,
    Bool,
    DiagnosticStatus,
    ErrorReply,
    ParamRequest,
    ParamInfo,
    ParamReply,
    NodeInfo,
)
