"""Which services and tool verbs exist: adding one is one line here.

A service module provides `add_arguments(parser)` and `run(ctx) -> int`
(see `buddybot.core.service.ServiceContext`). Modules are imported only
when used, so `buddybot --help` stays fast and a service whose optional
dependency is missing does not break the others.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass
from types import ModuleType


@dataclass(frozen=True)
class Entry:
    name: str
    module: str
    help: str

    def exists(self) -> bool:
        """Whether the module is present in this installation."""
        try:
            return importlib.util.find_spec(self.module) is not None
        except ModuleNotFoundError:
            return False

    def load(self) -> ModuleType:
        return importlib.import_module(self.module)


SERVICES: tuple[Entry, ...] = (
    Entry("radar-bridge", "buddybot.radar.bridge", "LD2410 radars over serial -> frames"),
    Entry("radar-presence", "buddybot.radar.presence_service", "radar frames -> presence"),
    Entry("camera", "buddybot.camera.capture", "capture camera frames and publish them"),
    Entry("face-detector", "buddybot.camera.detector", "BlazeFace face detection -> face position"),
    Entry("controller", "buddybot.controller.service", "social behaviour: eyes, gaze, greetings"),
    Entry("eyes", "buddybot.eyes.driver_service", "eye control -> direction, pupil, lids"),
    Entry("eye-renderer", "buddybot.eyes.renderer", "web page drawing the eyes, one per display"),
    Entry("audio", "buddybot.audio.action", "play_sound action server"),
    Entry("audio-player", "buddybot.audio.player_service", "plays sound files (miniaudio)"),
)

TOOLS: tuple[Entry, ...] = (
    Entry("radar", "buddybot.radar.tool", "LD2410 configuration tools"),
)


def service(name: str) -> Entry | None:
    return next((e for e in SERVICES if e.name == name), None)


def available_services() -> list[Entry]:
    return [e for e in SERVICES if e.exists()]
