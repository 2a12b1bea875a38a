"""Which files `audio/play_file` may open: configured sounds and sound folders only.

Anyone on the bus can ask the player to play something, so a request must
not become a way to read arbitrary files or to learn whether a path exists.
A request names a configured sound (trusted: it comes from the config
file) or a file inside one of the allowed folders, compared after symlinks
and `..` are resolved. Everything else gets `REFUSAL`, the same text
whatever the reason (missing, unreadable, a directory, outside), so the
reply tells nothing about the file system.

Path logic only: nothing is opened or decoded here.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from buddybot.audio import sounds as snd

REFUSAL = ("not an allowed sound (play_file takes a configured sound name or a file "
           "inside [audio_player] sound_dirs)")
"""The one answer for every request outside the allowed sounds."""


def real(path: Path) -> Path | None:
    """`path` with symlinks and `..` resolved (None for a path the OS rejects,
    such as one with a NUL byte)."""
    try:
        return Path(os.path.realpath(path))
    except (OSError, ValueError):
        return None


def sound_dirs(configured: Iterable[str] | None, sounds: dict[str, str],
               config_dir: Path | None) -> tuple[Path, ...]:
    """The folders play_file may read, resolved.

    `configured` (`[audio_player] sound_dirs`, relative to the config
    file's folder) wins; None means the package's own `sounds/` plus the
    folder of every configured sound file, which is what a robot plays.
    """
    if configured is not None:
        base = config_dir or Path.cwd()
        wanted = [base / Path(folder).expanduser() for folder in configured]
    else:
        wanted = [snd.PACKAGE_DIR / "sounds"]
        for value in sounds.values():
            try:
                sound = snd.parse_sound(value, config_dir)
            except ValueError:
                continue  # an unusable entry is reported when it is played
            if isinstance(sound, snd.FileSound):
                wanted.append(sound.path.parent)
    found: list[Path] = []
    for folder in wanted:
        resolved = real(folder)
        if resolved is not None and resolved not in found:
            found.append(resolved)
    return tuple(found)


def allowed_file(request: str, dirs: tuple[Path, ...]) -> Path | None:
    """The resolved file a request may play, or None (answer `REFUSAL`).

    An absolute path must resolve inside a folder. A relative one names the
    entry of the first folder that has it (else of the first folder, so a
    missing file says so), which must resolve inside a folder too: a
    symlink in a sound folder cannot lead out of it.
    """
    raw = Path(request)
    if raw.is_absolute():
        chosen: Path | None = raw
    else:
        chosen = next((folder / raw for folder in dirs if _lexists(folder / raw)),
                      dirs[0] / raw if dirs else None)
    resolved = None if chosen is None else real(chosen)
    if resolved is None or not any(resolved != d and resolved.is_relative_to(d) for d in dirs):
        return None
    return resolved


def _lexists(path: Path) -> bool:
    try:
        return os.path.lexists(path)
    except (OSError, ValueError):  # e.g. a NUL byte
        return False
