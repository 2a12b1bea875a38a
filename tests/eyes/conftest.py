"""Browser fixtures: Debian's chromium driven by Playwright (never a downloaded browser)."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update",
]


def chromium_path() -> str | None:
    return shutil.which("chromium")


@pytest.fixture(scope="module")
def chromium() -> Iterator[Any]:
    """A headless Chromium for this module's tests; skipped when chromium is absent."""
    path = chromium_path()
    if path is None:
        pytest.skip("Debian chromium not installed: run scripts/chromium.sh (CI installs it)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright not installed")
    with sync_api.sync_playwright() as pw:
        launched = pw.chromium.launch(executable_path=path, args=CHROMIUM_ARGS)
        try:
            yield launched
        finally:
            launched.close()


@pytest.fixture
def browser(chromium: Any) -> Iterator[Any]:
    """The module's Chromium; every page a test opened is closed after it, passed
    or failed, so no page of an earlier test keeps running scripts (and
    reconnecting to a server that is gone) beside the next test's."""
    yield chromium
    for context in list(chromium.contexts):
        context.close()


def screenshot(page: Any, directory: Path, name: str | None = None) -> np.ndarray:
    """The page as a BGR image; saved as `directory/name.png` for a person to look
    at when `name` is given."""
    png = page.screenshot()
    if name:
        directory.mkdir(parents=True, exist_ok=True)
        (directory / f"{name}.png").write_bytes(png)
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img
