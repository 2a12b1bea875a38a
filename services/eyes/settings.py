"""Config tables `[eyes]` and `[eye_renderer]` (pure msgspec structs)."""

from __future__ import annotations

import msgspec


class EyesSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    pass


class EyeRendererSettings(msgspec.Struct, forbid_unknown_fields=True, kw_only=True):
    host: str = "127.0.0.1"
    port: int = 8080
    browser: bool = True
