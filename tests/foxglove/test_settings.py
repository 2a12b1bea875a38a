"""Config table `[foxglove]` (services/foxglove/settings.py), pure."""

from __future__ import annotations

from buddybot.foxglove.settings import FoxgloveSettings


def test_defaults() -> None:
    s = FoxgloveSettings()
    assert (s.host, s.port, s.images, s.max_image_fps) == ("127.0.0.1", 8765, True, 10.0)
