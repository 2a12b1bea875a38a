"""`[identity]`: off by default, the vote's rules checked, the gallery in the state directory."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest

from buddybot.identity.settings import IdentitySettings, state_dir


def test_identity_is_opt_in() -> None:
    assert IdentitySettings().enabled is False


def test_more_votes_than_the_window_is_refused() -> None:
    with pytest.raises(msgspec.ValidationError, match="votes_needed"):
        msgspec.convert({"votes_needed": 6, "vote_window": 5}, IdentitySettings)


def test_retention_is_positive_days_or_none() -> None:
    assert msgspec.convert({"retention_days": 30}, IdentitySettings).retention_days == 30
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert({"retention_days": 0}, IdentitySettings)


def test_the_state_directory(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("STATE_DIRECTORY", "/var/lib/buddybot")
    assert state_dir() == Path("/var/lib/buddybot")
    monkeypatch.delenv("STATE_DIRECTORY")
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    assert state_dir() == tmp_path / "buddybot"
    monkeypatch.setenv("XDG_STATE_HOME", "relative")  # the XDG spec: ignored
    monkeypatch.setenv("HOME", str(tmp_path))
    assert state_dir() == tmp_path / ".local" / "state" / "buddybot"
