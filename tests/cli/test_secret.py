"""`buddybot secret show|rotate|revoke`: the files the web surfaces read."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from buddybot.cli import main
from buddybot.web import auth as web_auth


@pytest.fixture
def state(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("BUDDYBOT_STATE_DIR", str(tmp_path))
    return tmp_path


def test_show_makes_the_secret_once_rotate_replaces_it_revoke_empties_it(
        state: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["secret", "show"]) == 0
    first = capsys.readouterr().out.strip()
    path = web_auth.secret_path("operator", state)
    assert web_auth.read_secret(path) == first and len(first) >= 40
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert main(["secret", "show", "operator"]) == 0
    assert capsys.readouterr().out.strip() == first
    assert main(["secret", "rotate"]) == 0
    assert "every operator session has ended" in capsys.readouterr().err
    assert web_auth.read_secret(path) not in (None, first)
    assert main(["secret", "revoke", "operator"]) == 0
    assert web_auth.read_secret(path) is None
    assert main(["secret", "show"]) == 1  # revoked stays revoked, show says how to renew
    assert "buddybot secret rotate operator" in capsys.readouterr().err
    assert main(["secret", "show", "foxglove"]) == 0
    assert capsys.readouterr().out.strip() != ""


def test_a_file_others_may_read_is_refused_with_one_line(
        state: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = web_auth.secret_path("viewer", state)
    web_auth.write_secret(path, "x" * 43)
    path.chmod(0o644)
    assert main(["secret", "show", "viewer"]) == 1
    err = capsys.readouterr().err
    assert "accessible to others" in err and len(err.strip().splitlines()) == 1


def test_unknown_roles_are_usage_errors(state: Path) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["secret", "show", "admin"])
    assert exited.value.code == 2
