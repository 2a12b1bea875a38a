"""Owner-only files: the one way BuddyBot keeps what others must not read.

The identity gallery (biometric data) and its key, and the web surfaces'
login secrets are such files, kept in the robot's state folder
(`state_dir`). All need the same two rules: a file is used only when it
is a regular file of this user that no one else may read or write, and it
is written atomically (a temporary file, fsynced, renamed, the folder
fsynced), owner-only from its first byte, so a crash leaves the old file
or the new one, never half of one, and never a moment where it is readable.
"""

from __future__ import annotations

import contextlib
import hmac
import os
import stat
from collections.abc import Mapping
from pathlib import Path


def state_dir(env: Mapping[str, str] | None = None) -> Path:
    """The robot's state folder: `$BUDDYBOT_STATE_DIR`, else systemd's
    `$STATE_DIRECTORY` (`StateDirectory=buddybot`: /var/lib/buddybot), else
    `$XDG_STATE_HOME/buddybot` (an absolute one: the XDG spec), else
    `~/.local/state/buddybot`."""
    env = os.environ if env is None else env
    for name in ("BUDDYBOT_STATE_DIR", "STATE_DIRECTORY"):
        value = env.get(name, "").split(":")[0]
        if value:
            return Path(value).expanduser()
    xdg = env.get("XDG_STATE_HOME", "")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".local" / "state"
    return base / "buddybot"


def private_problem(st: os.stat_result, path: Path, advice: str) -> str | None:
    """Why `path` (whose stat is `st`) is not a private file of ours; None when it is.
    `advice` (what the file holds, what to do) ends the text when others may read it."""
    if not stat.S_ISREG(st.st_mode):
        return f"{path} is not a regular file"
    if st.st_uid != os.getuid():
        return f"{path} belongs to uid {st.st_uid}, not to this user ({os.getuid()})"
    if st.st_mode & 0o077:
        return f"{path} is accessible to others (mode {stat.S_IMODE(st.st_mode):o}): {advice}"
    return None


def secret_file(name: str, folder: Path | None = None) -> Path:
    """A named secret of the robot: `secrets/<name>` in its state folder."""
    return (folder if folder is not None else state_dir()) / "secrets" / name


def read_secret_text(path: Path, limit: int, advice: str) -> str | None:
    """The text of a secret file, stripped; None when absent or empty (revoked);
    NotPrivate as `read_private`."""
    data = read_private(path, limit, advice)
    text = "" if data is None else data.decode("ascii", "replace").strip()
    return text or None


OPERATOR_SECRET = "operator"
"""The secret an operator shows (`secrets/operator`: the dashboard's operator login)."""


def operator_secret(folder: Path | None = None) -> str:
    """The robot's operator secret ("" when there is none, it is revoked, or this
    user may not read it): what an operator's program shows as `credential`."""
    try:
        return read_secret_text(secret_file(OPERATOR_SECRET, folder), 512,
                                "it lets a program operate the robot; chmod 600 it") or ""
    except (NotPrivate, OSError):
        return ""


def is_operator(credential: str, folder: Path | None = None) -> bool:
    """Whether `credential` is the robot's operator secret (read each time: a
    rotated or revoked secret counts at once)."""
    want = operator_secret(folder) if credential else ""
    return bool(want) and hmac.compare_digest(credential.encode(), want.encode())


class NotPrivate(Exception):
    """A file that cannot be used as a private one; the text says why."""


def read_private(path: Path, limit: int, advice: str) -> bytes | None:
    """Up to `limit` + 1 bytes of the private file `path` (so a caller sees it is
    too long); None when there is none; NotPrivate when it cannot be opened or
    others may use it (`private_problem`, ending with `advice`). A symlink is
    never followed."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise NotPrivate(f"cannot open {path}: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as f:
        problem = private_problem(os.fstat(f.fileno()), path, advice)
        if problem is not None:
            raise NotPrivate(problem)
        return f.read(limit + 1)


def write_private(path: Path, data: bytes) -> None:
    """Replace `path` with `data` atomically, owner-only (its folder made 0700 when new)."""
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = folder / f".{path.name}.{os.getpid()}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | getattr(os, "O_NOFOLLOW", 0),
                 0o600)
    try:
        os.fchmod(fd, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    dir_fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)
