"""Config table `[dashboard]` (a pure msgspec struct).

Defaults let `buddybot up` serve the page on this machine only; see
docs/dashboard.md for opening it from a laptop (and why that needs care:
the page has buttons that act on the robot).
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from buddybot.runtime.endpoints import Host, Port, WebSurface


class DashboardSettings(WebSurface, forbid_unknown_fields=True, kw_only=True):
    """`[dashboard]`: the live dashboard page and its server.

    Live (`buddybot param set dashboard ...` applies at once): what the pages
    cost the robot, the image rate and JPEG quality (from the next image) and
    how many pages may connect (from the next connection; pages already
    connected stay). Restart-only: where it serves, which camera it watches,
    the history it keeps and the eye page it shows, all decided at start.
    """

    # Loopback by default: anyone who can open the page can press its buttons.
    host: Annotated[Host, msgspec.Meta(
        description="address the page is served on (empty or 0.0.0.0: every "
        "interface, so a laptop on the robot's network can open it)")] = "127.0.0.1"
    port: Annotated[Port, msgspec.Meta(
        description="HTTP port (0: any free port)")] = 8090
    # The face detector's default camera ([face_detector] camera); kept as a
    # literal because areas do not import each other.
    camera: Annotated[str, msgspec.Meta(
        min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_-]+$", examples=["side", "rear"],
        description="camera name whose images and faces are shown")] = "front"
    # Images are re-encoded as JPEG per page frame: this bounds the CPU the
    # page costs the robot (and the Wi-Fi it uses).
    max_image_fps: Annotated[float, msgspec.Meta(
        ge=0.5, le=60.0, extra={"live": True},
        description="camera images sent to the pages per second, at most")] = 10.0
    history_s: Annotated[float, msgspec.Meta(
        ge=2.0, le=600.0, description="seconds of radar distance history drawn")] = 30.0
    jpeg_quality: Annotated[int, msgspec.Meta(
        ge=10, le=100, extra={"live": True},
        description="JPEG quality of the images sent to the pages")] = 70
    # Empty: the eye renderer's page on the host the dashboard was loaded
    # from, at [eye_renderer] port.
    eye_url: Annotated[str, msgspec.Meta(
        max_length=2048, pattern=r"^(https?://\S+)?$",
        examples=["http://buddy.local:8080/eyes?eye=both", "http://10.0.0.5:8080/eyes"],
        description="URL of the eye page shown in the dashboard (empty: the eye renderer "
        "on the dashboard's host)")] = ""
    # `buddybot up --eye-port` moves the eye pages without changing the config:
    # `up` can hand the same port to the dashboard with --eye-port.
    eye_port: Annotated[Port, msgspec.Meta(
        description="port of the eye renderer for the derived eye URL "
        "(0: [eye_renderer] port)")] = 0
    params_period_s: Annotated[float, msgspec.Meta(
        ge=0.5, le=60.0, description="seconds between reads of radar-presence's live "
        "parameters (range and holds)")] = 3.0
    max_pages: Annotated[int, msgspec.Meta(
        ge=1, le=64, extra={"live": True},
        description="dashboard pages connected at once at most (lowering it cuts no page "
        "already connected)")] = 8
    # The operator's lease ends when no page is left to operate it from, so a
    # closed laptop never keeps the eyes from the robot's own behaviour.
    lease_idle_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0, extra={"live": True},
        description="seconds with no dashboard page open after which the operator's "
        "control (its lease) is given back; a reload keeps it")] = 30.0
    # Beyond loopback anyone on the network could press the buttons: a login
    # (the per-robot secrets of `buddybot secret`) is asked for there.
    login: Annotated[Literal["auto", "always"], msgspec.Meta(
        description="when the page asks for a login: auto (only when served beyond "
        "loopback) or always")] = "auto"
    session_hours: Annotated[float, msgspec.Meta(
        ge=0.1, le=720.0, description="hours a login lasts (rotating or revoking the "
        "secret ends it at once)")] = 12.0
    # Paths relative to the config file's folder; both or neither.
    tls_cert: Annotated[str, msgspec.Meta(
        max_length=4096, examples=["/etc/buddybot/certs/robot.crt"],
        description="PEM certificate (chain) to serve HTTPS with (empty: plain HTTP)")] = ""
    tls_key: Annotated[str, msgspec.Meta(
        max_length=4096, examples=["/etc/buddybot/certs/robot.key"],
        description="PEM private key of tls_cert")] = ""
