"""The kiosk browser's command line (services/eyes/kiosk.py), pure."""

from __future__ import annotations

from pathlib import Path

from buddybot.eyes import kiosk, placement
from buddybot.eyes.placement import Display

D2 = Display(800, 0, 800, 480, "HDMI-2")


def test_kiosk_command_positions_an_app_window_on_its_display(tmp_path: Path) -> None:
    win = placement.Window("right", 2, D2)
    argv = kiosk.command("/usr/bin/chromium", kiosk.page_url("http://127.0.0.1:8080/", "right"),
                         win, tmp_path / "right", ["--disable-gpu"])
    assert argv[0] == "/usr/bin/chromium"
    assert "--app=http://127.0.0.1:8080/eyes?eye=right" in argv
    assert "--window-position=800,0" in argv and "--window-size=800,480" in argv
    assert "--kiosk" in argv and f"--user-data-dir={tmp_path / 'right'}" in argv
    assert argv[-1] == "--disable-gpu"


def test_find_browser_explicit_missing_is_none() -> None:
    assert kiosk.find_browser("/nonexistent/chromium") is None
