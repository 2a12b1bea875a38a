"""The eye tests' headless Chromium (Debian's, driven by Playwright) for the dashboard's."""

from __future__ import annotations

from ..eyes.conftest import browser, chromium

__all__ = ["browser", "chromium"]
