"""Which services and tool verbs exist: adding one is one line here.

A service module provides `add_arguments(parser)` and `run(ctx) -> int`
(see `buddybot.runtime.service.ServiceContext`), and names its config table
and the msgspec struct that table decodes into: the configuration is
assembled from these entries (`buddybot.runtime.config`), so the runtime
never imports an area. Modules are imported only when used, so
`buddybot --help` stays fast and a service whose optional dependency is
missing does not break the others.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from buddybot.runtime.health import DoctorHooks


@dataclass(frozen=True)
class Entry:
    name: str
    module: str
    help: str
    table: str | None = None
    """The service's config table (`[radar_bridge]`), None for a tool."""
    settings: str | None = None
    """`module:Struct` the table decodes into (imported when a config is read)."""
    doctor: str | None = None
    """`module:NAME` of the service's `health.DoctorHooks` (its device checks, the
    packages it needs, its stream's rate), imported only when doctor runs, so
    doctor stays area-free."""
    on_request: bool = False
    """Started by `up` only when asked (`up --foxglove`, or its table's
    `enabled = true`), never by default."""
    up_flag: str | None = None
    """The `up` option that asks for an on-request service (`--foxglove`)."""
    simulation: bool = False
    """Started by `up` only when a sensor is simulated (the world's truth)."""

    def exists(self) -> bool:
        """Whether the module is present in this installation."""
        try:
            return importlib.util.find_spec(self.module) is not None
        except ModuleNotFoundError:
            return False

    def load(self) -> ModuleType:
        return importlib.import_module(self.module)

    def doctor_hooks(self) -> DoctorHooks | None:
        """The service's part of doctor, None when it has none."""
        if self.doctor is None:
            return None
        module, _, name = self.doctor.partition(":")
        hooks: DoctorHooks = getattr(importlib.import_module(module), name)
        return hooks

    def settings_type(self) -> type[Any]:
        """The msgspec struct of this service's config table."""
        if self.settings is None:
            raise LookupError(f"{self.name} has no config table")
        module, _, name = self.settings.partition(":")
        kind: type[Any] = getattr(importlib.import_module(module), name)
        return kind


SERVICES: tuple[Entry, ...] = (
    Entry("radar-bridge", "buddybot.radar.bridge", "LD2410 radars over serial -> frames",
          "radar_bridge", "buddybot.radar.settings:RadarBridgeSettings",
          doctor="buddybot.radar.doctor:BRIDGE"),
    Entry("radar-presence", "buddybot.radar.presence_service", "radar frames -> presence",
          "radar_presence", "buddybot.radar.settings:RadarPresenceSettings"),
    Entry("camera", "buddybot.camera.capture", "capture camera frames and publish them",
          "camera", "buddybot.camera.settings:CameraSettings",
          doctor="buddybot.camera.doctor:CAPTURE"),
    Entry("face-detector", "buddybot.camera.detector",
          "BlazeFace face detection -> face position",
          "face_detector", "buddybot.camera.settings:FaceDetectorSettings",
          doctor="buddybot.camera.doctor:DETECTOR"),
    Entry("controller", "buddybot.controller.service", "social behaviour: eyes, gaze, greetings",
          "controller", "buddybot.controller.settings:ControllerSettings"),
    Entry("people", "buddybot.people.service",
          "radar presence + face -> persons, zones, engagement",
          "people", "buddybot.people.settings:PeopleSettings"),
    Entry("eyes", "buddybot.eyes.driver_service", "eye control -> direction, pupil, lids",
          "eyes", "buddybot.eyes.settings:EyesSettings"),
    Entry("eye-renderer", "buddybot.eyes.renderer", "web page drawing the eyes, one per display",
          "eye_renderer", "buddybot.eyes.settings:EyeRendererSettings"),
    Entry("audio", "buddybot.audio.action", "play_sound action server",
          "audio", "buddybot.audio.settings:AudioSettings", doctor="buddybot.audio.doctor:ACTION"),
    Entry("audio-player", "buddybot.audio.player_service", "plays sound files (miniaudio)",
          "audio_player", "buddybot.audio.settings:AudioPlayerSettings",
          doctor="buddybot.audio.doctor:PLAYER"),
    Entry("dashboard", "buddybot.dashboard.service", "live web page of what the robot perceives",
          "dashboard", "buddybot.dashboard.settings:DashboardSettings"),
    Entry("sim", "buddybot.sim.service",
          "the simulated world's truth on sim/world (started by up while simulating)",
          "sim", "buddybot.sim.settings:SimSettings", simulation=True),
    Entry("foxglove", "buddybot.foxglove.service",
          "Foxglove WebSocket bridge: every key live in the Foxglove app",
          "foxglove", "buddybot.foxglove.settings:FoxgloveSettings", on_request=True,
          up_flag="--foxglove"),
    Entry("identity", "buddybot.identity.service",
          "who the followed face is, by name, for people who consented (enrol/forget/list)",
          "identity", "buddybot.identity.settings:IdentitySettings", on_request=True,
          up_flag="--identity"),
    Entry("ros2-bridge", "buddybot.ros2.service",
          "ROS 2 bridge: the robot's topics on a ROS 2 graph (rmw_zenoh)",
          "ros2", "buddybot.ros2.settings:Ros2Settings", on_request=True, up_flag="--ros2"),
)

TOOLS: tuple[Entry, ...] = (
    Entry("radar", "buddybot.radar.tool", "LD2410 configuration tools"),
)


def service(name: str) -> Entry | None:
    return next((e for e in SERVICES if e.name == name), None)


def available_services() -> list[Entry]:
    return [e for e in SERVICES if e.exists()]
