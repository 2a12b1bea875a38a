"""Config tables `[eyes]` and `[eye_renderer]` (pure msgspec structs).

Defaults are chosen so `buddybot up` works with no config at all; the
reasons are next to each field and in docs/eyes.md.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec


def _default_curve() -> list[list[float]]:
    # Same values as buddybot.eyes.driver.DEFAULT_PUPIL_CURVE (kept import-free here).
    return [[30.0, 75.0], [100.0, 55.0], [300.0, 30.0]]


class EyesSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[eyes]`: the eyes driver."""

    # (distance_cm, dilation %) points of the pupil curve, distances increasing,
    # dilation never increasing: near -> large pupils, far -> small; linear in
    # between, flat beyond the ends, always clamped to 0..100.
    # Live (`extra={"live": True}`): `buddybot param set eyes ...` applies at once.
    pupil_curve: Annotated[list[list[float]], msgspec.Meta(extra={"live": True})] = (
        msgspec.field(default_factory=_default_curve))
    # Dilation when eye control carries no distance (target_distance_cm = 0).
    unknown_distance_percent: Annotated[float, msgspec.Meta(
        ge=0.0, le=100.0, extra={"live": True},
        description="pupil dilation in % when eye control carries no distance")] = 50.0
    # Lid overrides per expression name: [top, bottom] for both eyes, or
    # [left_top, left_bottom, right_top, right_bottom]; 0/0 open, 50/50 closed.
    lids: Annotated[dict[str, list[float]], msgspec.Meta(extra={"live": True})] = msgspec.field(
        default_factory=dict)


EyeName = Literal["left", "right"]


class EyeRendererSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    """`[eye_renderer]`: the web eye renderer and its kiosk windows."""

    # Loopback by default: a tablet or phone as an eye needs host = "0.0.0.0".
    host: Annotated[str, msgspec.Meta(
        max_length=253, description="address the pages are served on (empty: every "
        "interface; 0.0.0.0 lets a tablet or phone be an eye)")] = "127.0.0.1"
    port: Annotated[int, msgspec.Meta(
        ge=0, le=65535, description="HTTP port (0: any free port)")] = 8080
    # Open kiosk Chromium windows (false = only serve the pages).
    browser: Annotated[bool, msgspec.Meta(
        description="open kiosk Chromium windows (false: only serve the pages)")] = True
    # Chromium executable; empty = first of chromium, chromium-browser, google-chrome.
    browser_path: Annotated[str, msgspec.Meta(
        description="Chromium executable (empty: found on PATH)")] = ""
    # Placement (docs/design.md section 4.5); empty/0 = not configured, defaults apply:
    # left eye on display 1, right eye on display 2, one display -> both on it.
    eyes: list[EyeName] = msgspec.field(default_factory=list)
    left_display: Annotated[int, msgspec.Meta(
        ge=0, le=64, description="display number (1 = leftmost) of the robot's left eye; "
        "0: the default placement")] = 0
    right_display: Annotated[int, msgspec.Meta(
        ge=0, le=64, description="display number (1 = leftmost) of the robot's right eye; "
        "0: the default placement")] = 0
    # Looks, sent to every page: iris colour and the gaze angle that puts the
    # iris at the edge of the eye (larger = calmer eyes).
    iris_color: Annotated[str, msgspec.Meta(
        pattern=r"^#[0-9a-fA-F]{6}$", examples=["#a05a2c"],
        description="iris colour, #rrggbb")] = "#2f7fd0"
    max_yaw_deg: Annotated[float, msgspec.Meta(
        gt=0.0, le=90.0, description="degrees of yaw that put the iris at the edge")] = 40.0
    max_pitch_deg: Annotated[float, msgspec.Meta(
        gt=0.0, le=90.0, description="degrees of pitch that put the iris at the edge")] = 30.0
    # At most this many pages connected at once (two kiosk windows, a few
    # phones); over it a new WebSocket is closed at once with code 1013 and a
    # reason, so a flood of connections cannot starve the real eyes.
    max_pages: Annotated[int, msgspec.Meta(
        ge=1, le=256, description="pages connected at once at most")] = 16
    # A page whose sends do not drain for this long (it stopped reading) is
    # dropped; a real page reconnects by itself and gets the whole state.
    page_stall_s: Annotated[float, msgspec.Meta(
        ge=0.2, le=60.0, description="seconds a page's sends may not drain before it is "
        "dropped")] = 2.0
    # Browser origins allowed to open the WebSocket besides the server's own
    # (same host and port), e.g. ["http://buddy.local:8080"]. A request with no
    # Origin header is not a browser page and is allowed.
    allowed_origins: list[Annotated[str, msgspec.Meta(
        pattern=r"^https?://[^/?#\s]+$", max_length=200, examples=["http://buddy.local:8080"],
    )]] = msgspec.field(default_factory=list)
