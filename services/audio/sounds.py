"""Sound names -> what to play: a file, or text to speak (pure path logic).

`[audio.sounds]` values are file paths, resolved relative to the config
file's folder, and when not found there relative to this package (so the
shipped defaults `sounds/greeting.wav` work from any config), or
`say:<text>` for text-to-speech. Nothing is read or played here; which
other files a play request may name is `access.py`'s rule.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from buddybot.contract.messages import AUDIO_SUFFIXES, TTS_PREFIX

PACKAGE_DIR = Path(__file__).resolve().parent


@dataclass(frozen=True)
class FileSound:
    path: Path


@dataclass(frozen=True)
class SpokenSound:
    text: str


Sound = FileSound | SpokenSound


def effective_sounds(configured: dict[str, str], defaults: dict[str, str]) -> dict[str, str]:
    """Configured names on top of the defaults: listing only `greeting` keeps `farewell`."""
    return {**defaults, **configured}


def resolve_file(value: str, config_dir: Path | None) -> Path:
    """A configured file path: absolute as is; relative to the config's folder when
    the file exists there, else the package's own copy (the shipped sounds)."""
    path = Path(value).expanduser()
    if path.is_absolute():
        return path
    if config_dir is not None and (config_dir / path).exists():
        return config_dir / path
    packaged = PACKAGE_DIR / path
    if packaged.exists() or config_dir is None:
        return packaged
    return config_dir / path


def parse_sound(value: str, config_dir: Path | None) -> Sound:
    """What a configured value means: `say:<text>` or a file path."""
    if value.startswith(TTS_PREFIX):
        text = value[len(TTS_PREFIX):].strip()
        if not text:
            raise ValueError("empty text after 'say:'")
        return SpokenSound(text)
    if not value.strip():
        raise ValueError("empty file path")
    return FileSound(resolve_file(value, config_dir))


def format_hint(path: Path) -> str:
    """A short reason to add to a decode error, from the file name."""
    suffix = path.suffix.lower()
    if suffix and suffix not in AUDIO_SUFFIXES:
        return f"unsupported format '{suffix}' (supported: WAV, FLAC, MP3, Ogg Vorbis)"
    return "not a valid WAV, FLAC, MP3 or Ogg Vorbis file (corrupt or truncated?)"
