"""The login rules: where a login is needed, secret files, signed session cookies."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from buddybot.web import auth as wa


@pytest.mark.parametrize(("host", "mode", "needed"), [
    ("127.0.0.1", "auto", False), ("127.0.0.2", "auto", False), ("::1", "auto", False),
    ("localhost", "auto", False), ("", "auto", True), ("0.0.0.0", "auto", True),
    ("10.0.0.5", "auto", True), ("buddy.local", "auto", True), ("127.0.0.1", "always", True),
])
def test_a_login_is_needed_beyond_loopback(host: str, mode: str, needed: bool) -> None:
    assert wa.login_required(host, mode) is needed


def test_state_dir_order() -> None:
    assert wa.state_dir({"BUDDYBOT_STATE_DIR": "/a", "STATE_DIRECTORY": "/b"}) == Path("/a")
    assert wa.state_dir({"STATE_DIRECTORY": "/b:/c"}) == Path("/b")
    assert wa.state_dir({"XDG_STATE_HOME": "/x"}) == Path("/x/buddybot")


def test_secrets_are_made_once_owner_only_and_revoked_ones_stay_revoked(tmp_path: Path) -> None:
    store = wa.SecretStore(tmp_path)
    assert store.ensure() == ["operator", "viewer"]
    path = wa.secret_path("operator", tmp_path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    first = store.current()
    assert first["operator"] and first["viewer"] and first["operator"] != first["viewer"]
    assert store.ensure() == []  # a second start keeps them
    assert store.current() == first
    wa.write_secret(path, "")  # revoke
    assert store.ensure() == []
    assert store.current()["operator"] is None


def test_a_secret_file_others_may_read_is_refused(tmp_path: Path) -> None:
    path = wa.secret_path("viewer", tmp_path)
    wa.write_secret(path, wa.new_secret())
    os.chmod(path, 0o644)
    with pytest.raises(wa.SecretError, match="accessible to others"):
        wa.read_secret(path)
    assert wa.SecretStore(tmp_path).current()["viewer"] is None  # nobody gets in with it
    with pytest.raises(ValueError, match="unknown role"):
        wa.secret_path("admin", tmp_path)


def test_login_picks_the_role_whose_secret_was_given() -> None:
    current = {"operator": "op-secret", "viewer": "view-secret"}
    assert wa.login_role("op-secret", current) == "operator"
    assert wa.login_role("view-secret", current) == "viewer"
    assert wa.login_role("wrong", current) is None
    assert wa.login_role("", {"operator": None, "viewer": None}) is None
    assert wa.login_role("x" * 300, {"operator": "x" * 300, "viewer": None}) is None


def test_cookies_are_signed_by_their_role_secret_and_expire() -> None:
    current: dict[str, str | None] = {"operator": "s1", "viewer": "s2"}
    cookie = wa.make_cookie("operator", "s1", 1000.0, 60.0)
    assert wa.check_cookie(cookie, current, 1000.0) == wa.Session("operator", 1060,
                                                              cookie.split(".")[2])
    assert wa.check_cookie(cookie, current, 1061.0) is None  # expired
    assert wa.check_cookie(cookie, {**current, "operator": "rotated"}, 1000.0) is None
    assert wa.check_cookie(cookie, {**current, "operator": None}, 1000.0) is None  # revoked
    forged = cookie.replace("operator", "viewer", 1)
    assert wa.check_cookie(forged, current, 1000.0) is None
    longer = cookie.replace(".1060.", ".9999999999.")
    assert wa.check_cookie(longer, current, 1000.0) is None
    for junk in (None, "", "a.b", "a.b.c.d.e", "operator.x.y.z", "🤖" * 600):
        assert wa.check_cookie(junk, current, 1000.0) is None


def test_tokens() -> None:
    assert wa.token_ok("abc", "abc")
    assert not wa.token_ok("abd", "abc")
    assert not wa.token_ok(None, "abc")
    assert not wa.token_ok("", None)
