"""Text-to-speech with espeak-ng, rendered once to a cached WAV file.

Optional: only used for `say:<text>` (a configured sound, or a goal
speaking any text). The file name is a hash of the text, so a restart
reuses the rendering and the first play of a spoken sound costs no
synthesis time. Goals may speak any text, so the cache keeps the
CACHE_FILES most recently rendered files and deletes older ones.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import tempfile
from pathlib import Path

CACHE_FILES = 256
"""Rendered texts kept (a 240-character text is about 0.7 MB)."""


class TtsError(Exception):
    """Speech could not be rendered; the message says why."""


ESPEAK = "espeak-ng"
"""The program that speaks: looked up on PATH when a text is rendered."""


def cache_dir() -> Path:
    return Path(tempfile.gettempdir()) / "buddybot-tts"


def render(text: str, *, voice: str = "en-us", folder: Path | None = None,
           timeout_s: float = 20.0) -> Path:
    """The WAV file speaking `text` (rendered on first use)."""
    exe = shutil.which(ESPEAK)
    if exe is None:
        raise TtsError("text-to-speech needs espeak-ng, which is not installed")
    folder = folder or cache_dir()
    folder.mkdir(parents=True, exist_ok=True)
    digest = hashlib.sha256(f"{voice}\0{text}".encode()).hexdigest()[:20]
    out = folder / f"{digest}.wav"
    if out.exists() and out.stat().st_size > 44:
        out.touch()
        return out
    partial = out.with_suffix(".part.wav")
    try:
        done = subprocess.run(
            [exe, "-v", voice, "-w", str(partial), "--", text],
            capture_output=True, timeout=timeout_s, check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise TtsError(f"espeak-ng failed: {exc}") from None
    if done.returncode != 0:
        err = done.stderr.decode(errors="replace").strip()
        raise TtsError(f"espeak-ng failed (exit {done.returncode}): {err}")
    partial.replace(out)
    prune(folder, CACHE_FILES)
    return out


def prune(folder: Path, keep: int) -> int:
    """Delete all but the `keep` most recently used WAV files; how many went."""
    files = []
    for path in folder.glob("*.wav"):
        if path.name.endswith(".part.wav"):
            continue  # being rendered now
        try:
            files.append((path.stat().st_mtime_ns, path))
        except OSError:
            continue  # deleted meanwhile by another process
    files.sort(reverse=True)
    gone = 0
    for _, path in files[keep:]:
        try:
            path.unlink()
            gone += 1
        except OSError:
            pass
    return gone
