"""Config tables `[eyes]` and `[eye_renderer]` (services/eyes/settings.py), pure."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.eyes.settings import EyeRendererSettings


@pytest.mark.parametrize(("table", "message"), [
    ({"max_pages": 0}, "max_pages"),
    ({"max_pages": 100000}, "max_pages"),
    ({"page_stall_s": 0}, "page_stall_s"),
    ({"allowed_origins": ["evil.example"]}, "allowed_origins"),
    ({"allowed_origins": ["http://a.example/path"]}, "allowed_origins"),
])
def test_renderer_limits_are_range_checked(table: dict[str, object], message: str) -> None:
    with pytest.raises(msgspec.ValidationError, match=message):
        msgspec.convert(table, EyeRendererSettings)
    assert EyeRendererSettings().max_pages == 16
