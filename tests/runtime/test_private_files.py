"""Owner-only files: written atomically at 0600, refused when others may read them."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from buddybot.runtime.private_files import private_problem, state_dir, write_private


def test_written_owner_only_in_an_owner_only_folder_and_replaced_whole(tmp_path: Path) -> None:
    path = tmp_path / "new" / "file"
    write_private(path, b"one")
    write_private(path, b"two")
    assert path.read_bytes() == b"two"
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert stat.S_IMODE(path.parent.stat().st_mode) == 0o700
    assert [p.name for p in path.parent.iterdir()] == ["file"]  # no temporary left
    assert private_problem(path.stat(), path, "advice") is None


def test_problems_name_the_file_and_end_with_the_advice(tmp_path: Path) -> None:
    path = tmp_path / "f"
    write_private(path, b"x")
    os.chmod(path, 0o640)
    problem = private_problem(path.stat(), path, "chmod 600 it")
    assert problem is not None and str(path) in problem and problem.endswith("chmod 600 it")
    assert "not a regular file" in (private_problem(tmp_path.stat(), tmp_path, "") or "")


def test_the_state_folder_every_service_shares() -> None:
    """One rule for every service (the identity service once ignored the first)."""
    assert state_dir({"BUDDYBOT_STATE_DIR": "/srv/robot2", "STATE_DIRECTORY": "/x"}) == \
        Path("/srv/robot2")
    assert state_dir({"STATE_DIRECTORY": "/var/lib/buddybot:/other"}) == \
        Path("/var/lib/buddybot")
    assert state_dir({"XDG_STATE_HOME": "/home/u/.state"}) == Path("/home/u/.state/buddybot")
    home = Path.home() / ".local" / "state" / "buddybot"
    assert state_dir({"XDG_STATE_HOME": "relative"}) == home  # the XDG spec: ignored
    assert state_dir({}) == home
