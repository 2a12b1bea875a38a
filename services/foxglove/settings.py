"""Config table `[foxglove]` (a pure msgspec struct).

Defaults serve this machine only: the Foxglove app on a laptop needs
`host = "0.0.0.0"` (docs/foxglove.md says why that needs care: the bridge
can set the eyes' expression and play sounds).
"""

from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from buddybot.runtime.endpoints import Host, Port, WebSurface

DEFAULT_ORIGINS = ("https://app.foxglove.dev", "file://")
"""The Foxglove web app's origin and the desktop app's (its pages are files)."""


class FoxgloveSettings(WebSurface, forbid_unknown_fields=True, kw_only=True):
    """`[foxglove]`: the Foxglove WebSocket bridge."""

    # Loopback by default: anyone who can connect can call the bridge's services.
    host: Annotated[Host, msgspec.Meta(
        description="address the WebSocket server listens on (0.0.0.0: "
        "every interface, so the Foxglove app on a laptop can connect)")] = "127.0.0.1"
    # Foxglove's own default port, the one the app proposes.
    port: Annotated[Port, msgspec.Meta(
        description="WebSocket port (0: any free port)")] = 8765
    images: Annotated[bool, msgspec.Meta(
        description="offer camera images (as foxglove.CompressedImage) while a client "
        "watches them")] = True
    # Raw frames are JPEG-compressed per sent frame: this bounds the CPU and
    # the Wi-Fi a viewer costs the robot.
    # Live (`buddybot param set foxglove max_image_fps 5`): applies to the next frame.
    max_image_fps: Annotated[float, msgspec.Meta(
        gt=0.0, le=60.0, extra={"live": True},
        description="images sent per camera key per second, at most")] = 10.0
    # A lease taken for a remote client ends when it goes quiet, so a Foxglove
    # window left open never keeps the eyes from the robot's own behaviour.
    lease_idle_s: Annotated[float, msgspec.Meta(
        gt=0.0, le=3600.0, extra={"live": True},
        description="seconds after the last `eyes/expression` call that the bridge "
        "gives its operator lease back")] = 10.0
    # Channels are made from keys seen on the bus, which anyone on it can
    # invent (`radar/<anything>/frames`): the table is bounded.
    max_channels: Annotated[int, msgspec.Meta(
        ge=1, le=4096, description="Foxglove channels at most (keys seen beyond are "
        "counted and not shown)")] = 256
    # Browser origins that may connect: the Foxglove web app and the desktop
    # app (an Electron page, Origin "file://"); pages served from this
    # machine's loopback always may. A client sending no Origin is a program,
    # not a page, and passes. Anything else gets 403 at the gate (gate.py).
    allowed_origins: Annotated[list[Annotated[str, msgspec.Meta(
        pattern=r"^(https?://[^/?#\s]+|file://|null)$", max_length=200,
        examples=["https://app.foxglove.dev", "http://studio.example.org:8080"])]],
        msgspec.Meta(max_length=64, description="browser origins allowed to connect "
                     "(pages from this machine's loopback always are)")] = msgspec.field(
        default_factory=lambda: list(DEFAULT_ORIGINS))
    # Beyond loopback anyone on the network could set expressions and play
    # sounds: a token (`buddybot secret show foxglove`) is asked for there.
    login: Annotated[Literal["auto", "always"], msgspec.Meta(
        description="when a client must bring the bridge's token: auto (only when "
        "served beyond loopback) or always")] = "auto"
