"""Config tables `[audio]` and `[audio_player]` (pure msgspec structs)."""

from __future__ import annotations

from typing import Literal

import msgspec


def _default_sounds() -> dict[str, str]:
    return {"greeting": "sounds/greeting.wav", "farewell": "sounds/farewell.wav"}


class AudioSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    sounds: dict[str, str] = msgspec.field(default_factory=_default_sounds)


class AudioPlayerSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    backend: Literal["auto", "null"] = "auto"
    device: str | None = None
    volume: float = 1.0
