"""The consented gallery: names and face embeddings, never images, in one owner-only file.

A face template is biometric data, kept only after an explicit enrolment
and easy to erase, so the file is treated as a secret and as untrusted
input at once:

* written atomically: a temporary file in the same folder (mode 0600 from
  its creation), flushed and fsynced, then renamed over the old one and the
  folder fsynced; a crash at any point leaves the old gallery or the new
  one, never half of one;
* refused on load, with a message that says what to do, when it is not
  owner-only (someone else could read the templates or plant a name),
  not ours (bad header, truncated, undecodable, or not signed with this
  robot's key: an edited or foreign file, e.g. a face renamed), or
  from another model (`model` differs: its vectors live in another space,
  and comparing them would give wrong names). The identity stage then runs
  without names rather than with wrong ones.

Layout: `MAGIC` (one line naming format and version), the HMAC-SHA256 of
the rest under the robot's gallery key (`load_key`: an owner-only file in
the state folder's `secrets/`), then a msgpack `GalleryFile` with each person's embeddings as raw
little-endian float32 bytes. Names are trimmed, 1-`MAX_NAME` characters,
no control characters; at most `MAX_PEOPLE` people of at most
`MAX_EMBEDDINGS` embeddings each (10,000 people load in about 0.3 s:
benchmarks/identity.py).
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import numpy as np
import numpy.typing as npt

from buddybot.runtime.private_files import (
    NotPrivate,
    private_problem,
    read_private,
    state_dir,
    write_private,
)

MAGIC = b"BUDDYBOT-GALLERY 2\n"
UNKEYED = b"BUDDYBOT-GALLERY 1\n"
"""The format before the key (a plain SHA-256): read once, on the first start
with a key, and written again signed; refused once the key exists."""
KEY_BYTES = 32
MAX_NAME = 64
MAX_PEOPLE = 10_000
MAX_EMBEDDINGS = 16
MAX_FILE_BYTES = 128 * 1024 * 1024
"""Largest gallery file read: MAX_PEOPLE full people of 512-number embeddings fit
(dlib's are 128); a larger file is refused before it is read into memory."""
DAY_S = 86_400.0


class GalleryError(Exception):
    """The gallery file cannot be used; the message says why and what to do."""


class BadName(ValueError):
    """A name that cannot be enrolled (empty, too long, control characters, taken)."""


class PersonRecord(msgspec.Struct, frozen=True):
    name: str
    embeddings: bytes
    """float32 little-endian, `dim` numbers per embedding."""
    enrolled_s: float
    last_seen_s: float


class GalleryFile(msgspec.Struct, frozen=True):
    model: str
    dim: int
    people: list[PersonRecord]


@dataclass
class Person:
    """One enrolled person: unit embeddings (K, dim), when enrolled and last recognised."""

    name: str
    embeddings: npt.NDArray[np.float32]
    enrolled_s: float
    last_seen_s: float


@dataclass
class Gallery:
    """The people of one model, in memory; `save`/`load` move it to and from its file."""

    model: str
    dim: int = 128
    people: dict[str, Person] = field(default_factory=dict)

    def enrol(self, name: str, embeddings: list[npt.NDArray[np.float32]], now_s: float,
              replace: bool = False) -> Person:
        """Add a person (or replace their embeddings when `replace`); returns the record.

        Refused: a bad name, an existing name without `replace`, no or too
        many embeddings, a vector of the wrong length or not of unit length,
        and a new person beyond MAX_PEOPLE.
        """
        key = valid_name(name)
        if key in self.people and not replace:
            raise BadName(f"{key!r} is already enrolled (enrol with replace to retake)")
        if key not in self.people and len(self.people) >= MAX_PEOPLE:
            raise BadName(f"the gallery is full ({MAX_PEOPLE} people): forget someone first")
        if not 1 <= len(embeddings) <= MAX_EMBEDDINGS:
            raise ValueError(f"need 1-{MAX_EMBEDDINGS} embeddings, got {len(embeddings)}")
        rows = np.stack([np.asarray(e, dtype=np.float32).ravel() for e in embeddings])
        if rows.shape[1] != self.dim:
            raise ValueError(f"embeddings have {rows.shape[1]} numbers, the model {self.dim}")
        norms = np.linalg.norm(rows, axis=1)
        if not (np.isfinite(rows).all() and np.allclose(norms, 1.0, atol=1e-3)):
            raise ValueError("embeddings must be finite unit vectors")
        person = Person(key, rows, now_s, now_s)
        self.people[key] = person
        return person

    def forget(self, name: str) -> bool:
        """Erase one person; False when nobody had that name."""
        return self.people.pop(name.strip(), None) is not None

    def forget_all(self) -> int:
        """Erase everyone; returns how many were erased."""
        count = len(self.people)
        self.people.clear()
        return count

    def seen(self, name: str, now_s: float) -> None:
        """Note that `name` was recognised now (what the retention limit counts from)."""
        if name in self.people:
            self.people[name].last_seen_s = max(self.people[name].last_seen_s, now_s)

    def expire(self, now_s: float, days: float) -> list[str]:
        """Forget everyone not seen for more than `days` days; returns their names."""
        if days <= 0:
            raise ValueError("the retention limit must be a positive number of days")
        old = [n for n, p in self.people.items() if now_s - p.last_seen_s > days * DAY_S]
        for name in old:
            del self.people[name]
        return old

    def table(self) -> tuple[list[str], npt.NDArray[np.float32]]:
        """(name of each row, rows (N, dim)): what `matching.best_match` takes."""
        names = [p.name for p in self.people.values() for _ in range(len(p.embeddings))]
        if not names:
            return [], np.zeros((0, self.dim), np.float32)
        return names, np.concatenate([p.embeddings for p in self.people.values()])


def valid_name(name: str) -> str:
    """`name` trimmed; BadName when empty, longer than MAX_NAME or holding control chars."""
    if not isinstance(name, str):
        raise BadName(f"a name is text, not {type(name).__name__}")
    key = name.strip()
    if not key:
        raise BadName("a name cannot be empty")
    if len(key) > MAX_NAME:
        raise BadName(f"a name has at most {MAX_NAME} characters, this one {len(key)}")
    if any(unicodedata.category(c).startswith("C") for c in key):
        raise BadName("a name cannot hold control or invisible characters")
    return key


def key_path(folder: Path | None = None) -> Path:
    """Where the robot keeps its gallery key (beside the web secrets)."""
    return (folder if folder is not None else state_dir()) / "secrets" / "gallery-key"


def load_key(path: Path) -> tuple[bytes, bool]:
    """(the gallery key, whether it was made now): made owner-only on first use;
    GalleryError when the file is unusable (not ours, readable by others, damaged)."""
    try:
        text = read_private(path, 4 * KEY_BYTES, "it signs the gallery; check who "
                            "changed it, then chmod 600 it")
    except NotPrivate as e:
        raise GalleryError(str(e)) from None
    if text is None:
        key = secrets.token_bytes(KEY_BYTES)
        try:
            write_private(path, key.hex().encode() + b"\n")
        except OSError as e:
            raise GalleryError(f"cannot make the gallery key {path}: {e.strerror}") from e
        return key, True
    try:
        key = bytes.fromhex(text.strip().decode())
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) != KEY_BYTES:
        raise GalleryError(f"the gallery key {path} is damaged: move it away and enrol "
                           "everyone again (the gallery it signed cannot be trusted)")
    return key, False


def _mac(key: bytes, body: bytes) -> bytes:
    return hmac.new(key, body, hashlib.sha256).digest()


def encode(g: Gallery, key: bytes) -> bytes:
    """The file's bytes for `g`, signed with `key`."""
    body = msgspec.msgpack.encode(GalleryFile(g.model, g.dim, [
        PersonRecord(p.name, p.embeddings.astype("<f4").tobytes(), p.enrolled_s, p.last_seen_s)
        for p in g.people.values()]))
    return MAGIC + _mac(key, body) + body


def decode(data: bytes, model: str, key: bytes, where: str = "gallery", *,
           unkeyed: bool = False) -> Gallery:
    """Bytes of a gallery file -> Gallery; GalleryError when they are not a usable
    gallery. `unkeyed`: a file of the format before the key is read too (the
    first start with a key: the caller writes it again, signed)."""
    if unkeyed and data.startswith(UNKEYED):
        digest, body = data[len(UNKEYED):len(UNKEYED) + 32], data[len(UNKEYED) + 32:]
        if len(digest) < 32 or hashlib.sha256(body).digest() != digest:
            raise GalleryError(f"{where} is truncated or corrupt (checksum mismatch)")
    elif data.startswith(UNKEYED):
        raise GalleryError(f"{where} is not signed with this robot's gallery key (a file "
                           "of the old format written after the key was made): enrol again")
    elif not data.startswith(MAGIC):
        raise GalleryError(f"{where} is not a BuddyBot gallery (or of another format version)")
    else:
        mac, body = data[len(MAGIC):len(MAGIC) + 32], data[len(MAGIC) + 32:]
        if len(mac) < 32 or not hmac.compare_digest(_mac(key, body), mac):
            raise GalleryError(f"{where} is not signed with this robot's gallery key: edited, "
                               "damaged or from another robot; not used (enrol again, or "
                               "put back this robot's file)")
    try:
        file = msgspec.msgpack.decode(body, type=GalleryFile)
    except msgspec.DecodeError as e:
        raise GalleryError(f"{where} is corrupt ({e})") from e
    if file.model != model:
        raise GalleryError(f"{where} was made with model {file.model!r}, this robot runs "
                           f"{model!r}: its faces must be enrolled again")
    if len(file.people) > MAX_PEOPLE:
        raise GalleryError(f"{where} holds {len(file.people)} people, more than {MAX_PEOPLE}")
    g = Gallery(model, file.dim)
    for rec in file.people:
        count = len(rec.embeddings) // 4
        if file.dim <= 0 or len(rec.embeddings) % 4 or count == 0 or count % file.dim:
            raise GalleryError(f"{where}: {rec.name[:MAX_NAME]!r} has malformed embeddings")
        rows = np.frombuffer(rec.embeddings, dtype="<f4").astype(np.float32)
        try:
            g.enrol(rec.name, list(rows.reshape(-1, file.dim)), rec.enrolled_s)
        except ValueError as e:
            raise GalleryError(f"{where}: bad entry {rec.name[:MAX_NAME]!r}: {e}") from e
        g.people[valid_name(rec.name)].last_seen_s = rec.last_seen_s
    return g


def check_private(st: os.stat_result, path: Path) -> None:
    """GalleryError unless `path` is a regular file of ours that no one else may read or write."""
    problem = private_problem(st, path, "it holds biometric data; check who changed it, "
                              "then chmod 600 it")
    if problem is not None:
        raise GalleryError(problem)


def load(path: Path, model: str, key: bytes, *, unkeyed: bool = False) -> Gallery:
    """The gallery at `path` (empty when there is no file yet); GalleryError when
    unusable (`decode`)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except FileNotFoundError:
        return Gallery(model)
    except OSError as e:
        raise GalleryError(f"cannot open {path}: {e.strerror}") from e
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(f.fileno())
        check_private(st, path)
        if st.st_size > MAX_FILE_BYTES:
            raise GalleryError(f"{path} is {st.st_size} bytes, more than a gallery can be "
                               f"({MAX_FILE_BYTES}): not read")
        data = f.read(MAX_FILE_BYTES + 1)
    return decode(data, model, key, str(path), unkeyed=unkeyed)


def save(path: Path, g: Gallery, key: bytes) -> None:
    """Write `g` to `path` atomically, owner-only, signed with `key` (the old file
    stays whole on any failure)."""
    write_private(path, encode(g, key))
