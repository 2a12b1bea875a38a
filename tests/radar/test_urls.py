"""A sensor's network URL is checked before it is opened (pure)."""

from __future__ import annotations

import pytest
import serial

from buddybot.radar.urls import url_problem


@pytest.mark.parametrize("url", [
    "socket://radar-esp32.local:4001", "socket://192.168.1.60:4002",
    "socket://127.0.0.1:4001?logging=debug", "rfc2217://ser2net.local:4001?poll_modem",
    "SOCKET://radar-esp32.local:4001",
    "/dev/ttyUSB0", "/tmp/ttyLD2410", "loop://", "spy:///dev/ttyUSB0",  # left to pyserial
])
def test_urls_that_can_open_pass(url: str) -> None:
    assert url_problem(url) is None


@pytest.mark.parametrize(("url", "why"), [
    ("socket://radar-esp32.local", "no port"),  # the typo: pyserial would say "'<=' not ..."
    ("socket://127.0.0.1:0", "no port"),
    ("socket://127.0.0.1:99999", "out of range"),
    ("socket://:4001", "no host"),  # pyserial would connect to this computer
    ("socket://127.0.0.1:4001?baud=256000", "unknown option 'baud'"),
    ("rfc2217://127.0.0.1:4001?nope", "unknown option 'nope'"),
    ("socket://127.0.0.1:4001/radar0", "unexpected path"),
])
def test_urls_that_can_never_open_are_named(url: str, why: str) -> None:
    problem = url_problem(url)
    assert problem is not None and why in problem
    assert "HOST:PORT" in problem or "known:" in problem


@pytest.mark.parametrize("url", ["socket://radar-esp32.local", "socket://127.0.0.1:99999",
                                 "socket://127.0.0.1:4001?baud=256000"])
def test_pyserial_cannot_open_them_either_but_says_less(url: str) -> None:
    """The check refuses only what pyserial could never open (it fails at open)."""
    with pytest.raises(serial.SerialException):
        serial.serial_for_url(url, timeout=0.1)
