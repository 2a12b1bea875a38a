"""Config tables `[eyes]` and `[eye_renderer]` (pure msgspec structs).

Defaults are chosen so `buddybot up` works with no config at all; the
reasons are next to each field and in docs/eyes.md.
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from buddybot.runtime.endpoints import Host, Port, WebSurface

DEFAULT_PUPIL_CURVE: tuple[tuple[float, float], ...] = ((30.0, 75.0), (100.0, 55.0), (300.0, 30.0))
"""(distance cm, dilation % of the iris) points: 30 cm (face close to the robot)
-> 75 %, 1 m (normal conversation) -> 55 %, 3 m (across the room) -> 30 %; flat
beyond both ends. Chosen so the change is visible over the radar's 0.3..3 m
range and steepest where people usually stand."""


def _default_curve() -> list[list[float]]:
    return [list(point) for point in DEFAULT_PUPIL_CURVE]


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
    # The arbiter's budget per lease (a token bucket): an app looping on eyes
    # commands is slowed down and counted, not obeyed.
    lease_actions_per_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=1000.0, extra={"live": True},
        description="eyes commands per second one lease may send (token bucket refill); "
                    "more are refused \"rate limited\"")] = 20.0
    lease_actions_burst: Annotated[float, msgspec.Meta(
        ge=1.0, le=1000.0, extra={"live": True},
        description="eyes commands one lease may send at once (token bucket depth)")] = 40.0


EyeName = Literal["left", "right"]


class EyeRendererSettings(WebSurface, forbid_unknown_fields=True, kw_only=True):
    """`[eye_renderer]`: the web eye renderer and its kiosk windows.

    Live (`extra={"live": True}`, `buddybot param set eye-renderer ...` applies
    at once): the looks (sent again to every page, which restyles in place)
    and the page limits (read on each connection or send). Restart-only:
    where the pages are served (a bound socket) and the kiosk windows
    (browser, placement, displays), which are decided once at start.
    """

    # Loopback by default: a tablet or phone as an eye needs host = "0.0.0.0".
    host: Annotated[Host, msgspec.Meta(
        description="address the pages are served on (empty: every "
        "interface; 0.0.0.0 lets a tablet or phone be an eye)")] = "127.0.0.1"
    port: Annotated[Port, msgspec.Meta(
        description="HTTP port (0: any free port)")] = 8080
    # Open kiosk Chromium windows (false = only serve the pages).
    browser: Annotated[bool, msgspec.Meta(
        description="open kiosk Chromium windows (false: only serve the pages)")] = True
    # Chromium executable; empty = first of chromium, chromium-browser, google-chrome.
    browser_path: Annotated[str, msgspec.Meta(
        description="Chromium executable (empty: found on PATH)")] = ""
    # Placement (docs/design.md section 4.5); empty/0 = not configured, defaults apply:
    # left eye on display 1, right eye on display 2, one display -> both on it.
    eyes: Annotated[list[EyeName], msgspec.Meta(
        description="which eyes get a kiosk window: left, right (empty: both)")] = (
        msgspec.field(default_factory=list))
    left_display: Annotated[int, msgspec.Meta(
        ge=0, le=64, description="display number (1 = leftmost) of the robot's left eye; "
        "0: the default placement")] = 0
    right_display: Annotated[int, msgspec.Meta(
        ge=0, le=64, description="display number (1 = leftmost) of the robot's right eye; "
        "0: the default placement")] = 0
    # Looks, sent to every page: iris colour and the gaze angle that puts the
    # iris at the edge of the eye (larger = calmer eyes).
    iris_color: Annotated[str, msgspec.Meta(
        pattern=r"^#[0-9a-fA-F]{6}$", examples=["#a05a2c"], extra={"live": True},
        description="iris colour of the eyeball style, #rrggbb")] = "#2f7fd0"
    max_yaw_deg: Annotated[float, msgspec.Meta(
        gt=0.0, le=90.0, extra={"live": True},
        description="degrees of yaw that put the iris at the edge")] = 40.0
    max_pitch_deg: Annotated[float, msgspec.Meta(
        gt=0.0, le=90.0, extra={"live": True},
        description="degrees of pitch that put the iris at the edge")] = 30.0
    # How the eyes are drawn (services/eyes/styles.json, docs/eyes.md): `glow`
    # (rounded glowing shapes) or `eyeball`, or a style from `style_file`.
    # Live: every page restyles in place. The name is checked against the
    # known styles when the renderer starts and on every change.
    style: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64, examples=["eyeball"], extra={"live": True},
        description="eye style: glow, eyeball or one from style_file")] = "glow"
    # A JSON file of styles added to the built-in ones (or changing them),
    # read once at start; relative to the config file's folder.
    style_file: Annotated[str, msgspec.Meta(
        max_length=4096, description="JSON file of extra eye styles, read at start "
        "(empty: the built-in ones only)")] = ""
    # At most this many pages connected at once (two kiosk windows, a few
    # phones); over it a new page takes the slot of the quietest one (a real
    # page pings every 2 s), so clients that only read cannot starve the eyes.
    max_pages: Annotated[int, msgspec.Meta(
        ge=1, le=256, extra={"live": True},
        description="pages connected at once at most (lowering it cuts no page already "
        "connected)")] = 16
    # A page whose sends do not drain for this long (it stopped reading) is
    # dropped; a real page reconnects by itself and gets the whole state.
    page_stall_s: Annotated[float, msgspec.Meta(
        ge=0.2, le=60.0, extra={"live": True},
        description="seconds a page's sends may not drain before it is dropped")] = 2.0
    # Browser origins allowed to open the WebSocket besides the server's own
    # (a name of allowed_hosts at its port), e.g. ["http://tablet.local:8080"]. A request with no
    # Origin header is not a browser page and is allowed.
    allowed_origins: Annotated[list[Annotated[str, msgspec.Meta(
        pattern=r"^https?://[^/?#\s]+$", max_length=200, examples=["http://buddy.local:8080"],
    )]], msgspec.Meta(extra={"live": True}, description="browser origins besides the "
                      "server's own allowed to open the eye WebSocket (checked on each "
                      "connection)")] = msgspec.field(default_factory=list)
    # The eyes' own motion, decided once for every page (services/eyes/motion.py):
    # spontaneous blinks at a random interval between these bounds (people at
    # rest: every 3-4 s on average, widely spread), a blink with every gaze
    # shift at least `gaze_blink_deg` large, and how far ahead of its start an
    # event is sent so every page has it in time (a few network delays).
    blink_interval_min_s: Annotated[float, msgspec.Meta(
        ge=0.3, le=60.0, extra={"live": True},
        description="shortest time between spontaneous blinks, s")] = 2.5
    blink_interval_max_s: Annotated[float, msgspec.Meta(
        ge=0.3, le=120.0, extra={"live": True},
        description="longest time between spontaneous blinks, s (below the shortest: "
        "every interval is the shortest)")] = 6.5
    gaze_blink_deg: Annotated[float, msgspec.Meta(
        ge=1.0, le=180.0, extra={"live": True},
        description="a gaze shift at least this large (degrees) comes with a blink")] = 18.0
    motion_lead_ms: Annotated[float, msgspec.Meta(
        ge=0.0, le=1000.0, extra={"live": True},
        description="ms between sending a blink or saccade and its start on every "
        "page")] = 60.0
