"""The gallery file: round trip, owner-only, atomic, every bad file refused clearly; names."""

from __future__ import annotations

import hashlib
import hmac
import subprocess
import sys
import textwrap
from pathlib import Path

import msgspec
import numpy as np
import pytest

from buddybot.identity import gallery as gal
from buddybot.identity.embedding import DIM, unit
from tests.identity.conftest import key

MODEL = "test-model/1"


def vec(seed: int) -> np.ndarray:
    return unit(np.random.default_rng(seed).normal(size=DIM))


def two_people() -> gal.Gallery:
    g = gal.Gallery(MODEL)
    g.enrol("Ada", [vec(1), vec(2)], now_s=100.0)
    g.enrol("Bob", [vec(3)], now_s=200.0)
    return g


@pytest.fixture
def path(tmp_path: Path) -> Path:
    p = tmp_path / "galleries" / "gallery.bin"  # beside, not in, the state folder
    gal.save(p, two_people(), key())
    return p


def test_round_trip_keeps_names_vectors_and_times(path: Path) -> None:
    g = gal.load(path, MODEL, key())
    assert list(g.people) == ["Ada", "Bob"]
    np.testing.assert_array_equal(g.people["Ada"].embeddings, np.stack([vec(1), vec(2)]))
    assert g.people["Bob"].enrolled_s == 200.0 and g.people["Bob"].last_seen_s == 200.0
    names, rows = g.table()
    assert names == ["Ada", "Ada", "Bob"] and rows.shape == (3, DIM)


def test_no_file_yet_is_an_empty_gallery(tmp_path: Path) -> None:
    g = gal.load(tmp_path / "none.bin", MODEL, key())
    assert g.people == {} and g.table()[1].shape == (0, DIM)


def test_the_file_is_owner_only_and_holds_no_image(path: Path) -> None:
    assert path.stat().st_mode & 0o777 == 0o600
    assert len(path.read_bytes()) < 4 * DIM * 3 + 400  # three vectors and names, nothing more
    assert [p.name for p in path.parent.iterdir()] == ["gallery.bin"]  # no temp file left


@pytest.mark.parametrize("mode", [0o666, 0o602, 0o620, 0o640, 0o604])
def test_a_file_others_can_read_or_write_is_refused(path: Path, mode: int) -> None:
    path.chmod(mode)
    with pytest.raises(gal.GalleryError, match="chmod 600"):
        gal.load(path, MODEL, key())


def test_a_symlink_is_refused(path: Path) -> None:
    link = path.parent / "link.bin"
    link.symlink_to(path)
    with pytest.raises(gal.GalleryError, match="cannot open"):
        gal.load(link, MODEL, key())


def write_private(path: Path, data: bytes) -> None:
    path.write_bytes(data)
    path.chmod(0o600)


@pytest.mark.parametrize("cut", [0, 5, len(gal.MAGIC) + 10, -1, -100])
def test_a_truncated_file_is_refused(path: Path, cut: int) -> None:
    write_private(path, path.read_bytes()[:cut])
    with pytest.raises(gal.GalleryError, match=r"not a BuddyBot gallery|truncated"):
        gal.load(path, MODEL, key())


def test_an_oversized_file_is_refused_unread(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(gal, "MAX_FILE_BYTES", path.stat().st_size - 1)
    with pytest.raises(gal.GalleryError, match="more than a gallery can be"):
        gal.load(path, MODEL, key())


def test_a_flipped_byte_is_refused(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[-50] ^= 0x40  # inside an embedding: would silently change a face unsigned
    write_private(path, bytes(data))
    with pytest.raises(gal.GalleryError, match="not signed with this robot's gallery key"):
        gal.load(path, MODEL, key())


def test_a_file_edited_by_anyone_without_the_key_is_refused(path: Path) -> None:
    """The old plain checksum let whoever could write the file rename a face (and fix the
    checksum); a file signed without this robot's key, or of the unkeyed format once
    the key exists, is refused. An unkeyed file is read once, when the key is new."""
    g = gal.load(path, MODEL, key())
    g.people["Mallory"] = g.people.pop("Ada")  # a face renamed
    g.people["Mallory"].name = "Mallory"
    body = gal.encode(g, key())[len(gal.MAGIC) + 32:]
    for forged in (gal.MAGIC + hashlib.sha256(body).digest() + body,
                   gal.encode(g, bytes(32)),
                   gal.UNKEYED + hashlib.sha256(body).digest() + body):
        write_private(path, forged)
        with pytest.raises(gal.GalleryError, match="not signed with this robot's gallery key"):
            gal.load(path, MODEL, key())
    migrated = gal.load(path, MODEL, key(), unkeyed=True)  # the first start with a key
    assert sorted(migrated.people) == ["Bob", "Mallory"]


def test_the_key_is_made_owner_only_once_and_a_bad_key_file_refused(tmp_path: Path) -> None:
    where = tmp_path / "keys" / "gallery-key"
    first, made = gal.load_key(where)
    assert made and len(first) == gal.KEY_BYTES
    assert where.stat().st_mode & 0o777 == 0o600
    assert gal.load_key(where) == (first, False)
    where.chmod(0o644)
    with pytest.raises(gal.GalleryError, match="accessible to others"):
        gal.load_key(where)
    write_private(where, b"not hex\n")
    with pytest.raises(gal.GalleryError, match="damaged"):
        gal.load_key(where)


@pytest.mark.parametrize("data", [b"", b"\x00" * 100, b"hello\n", bytes(range(256)) * 16],
                         ids=["empty", "zeros", "text", "binary"])
def test_garbage_is_refused(path: Path, data: bytes) -> None:
    write_private(path, data)
    with pytest.raises(gal.GalleryError, match="not a BuddyBot gallery"):
        gal.load(path, MODEL, key())


def with_checksum(body: bytes) -> bytes:
    """`body` as a file this robot wrote (signed with its key)."""
    return gal.MAGIC + hmac.new(key(), body, hashlib.sha256).digest() + body


@pytest.mark.parametrize("body", [
    b"\xc1",  # not msgpack
    b"\x93\xa1x\x05\x90",  # msgpack of the wrong shape
])
def test_a_well_signed_but_undecodable_body_is_refused(path: Path, body: bytes) -> None:
    write_private(path, with_checksum(body))
    with pytest.raises(gal.GalleryError, match="corrupt"):
        gal.load(path, MODEL, key())


@pytest.mark.parametrize("record", [
    gal.PersonRecord("", np.ones(DIM, "<f4").tobytes(), 0, 0),  # empty name
    gal.PersonRecord("x" * 10_000, vec(1).tobytes(), 0, 0),  # 10 kB name
    gal.PersonRecord("Ada", b"\x00\x01\x02", 0, 0),  # not whole floats
    gal.PersonRecord("Ada", np.zeros(DIM, "<f4").tobytes(), 0, 0),  # not a unit vector
    gal.PersonRecord("Ada", np.full(DIM, np.nan, "<f4").tobytes(), 0, 0),
])
def test_a_bad_entry_is_refused(path: Path, record: gal.PersonRecord) -> None:
    write_private(path, with_checksum(msgspec.msgpack.encode(gal.GalleryFile(MODEL, DIM,
                                                                              [record]))))
    with pytest.raises(gal.GalleryError, match=r"bad entry|malformed"):
        gal.load(path, MODEL, key())


def test_a_file_of_another_model_is_refused(path: Path) -> None:
    with pytest.raises(gal.GalleryError, match="enrolled again"):
        gal.load(path, "other-model/2", key())


def test_a_failure_before_the_rename_leaves_the_old_file(
        path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    before = path.read_bytes()
    g = gal.load(path, MODEL, key())
    g.forget("Ada")

    def broken(*_: object) -> None:
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(gal.os, "replace", broken)
    with pytest.raises(OSError):
        gal.save(path, g, key())
    assert path.read_bytes() == before
    assert [p.name for p in path.parent.iterdir()] == ["gallery.bin"]


@pytest.mark.integration
def test_a_process_killed_mid_write_leaves_the_old_file(path: Path) -> None:
    """A child dies (os._exit, no cleanup) after writing its temp file, before the rename."""
    before = path.read_bytes()
    child = textwrap.dedent(f"""
        import os, sys
        import numpy as np
        from buddybot.identity import gallery as gal
        g = gal.Gallery({MODEL!r})
        for i in range(500):
            v = np.random.default_rng(i).normal(size=128).astype(np.float32)
            g.enrol(f"p{{i}}", [v / np.linalg.norm(v)], now_s=0.0)
        gal.os.replace = lambda *a: os._exit(9)
        gal.save(gal.Path(sys.argv[1]), g, bytes(32))
    """)
    run = subprocess.run([sys.executable, "-c", child, str(path)], timeout=60)
    assert run.returncode == 9
    assert path.read_bytes() == before
    assert list(gal.load(path, MODEL, key()).people) == ["Ada", "Bob"]
    leftovers = [p for p in path.parent.iterdir()
                 if p.name not in ("gallery.bin", "state", "secrets")]
    assert leftovers and all(p.stat().st_mode & 0o777 == 0o600 for p in leftovers)
    gal.save(path, gal.load(path, MODEL, key()), key())  # a later save works beside it


@pytest.mark.parametrize("name", ["", "   ", "x" * 10_000, "a\nb", "tab\there", "\u200b"])
def test_bad_names_are_refused(name: str) -> None:
    with pytest.raises(gal.BadName):
        gal.Gallery(MODEL).enrol(name, [vec(1)], now_s=0.0)


def test_names_are_trimmed_and_may_be_any_language() -> None:
    g = gal.Gallery(MODEL)
    assert g.enrol("  Zoë 李  ", [vec(1)], now_s=0.0).name == "Zoë 李"
    assert g.enrol("x" * gal.MAX_NAME, [vec(2)], now_s=0.0).name == "x" * gal.MAX_NAME


def test_an_existing_name_is_refused_unless_replaced() -> None:
    g = two_people()
    with pytest.raises(gal.BadName, match="already enrolled"):
        g.enrol("Ada", [vec(9)], now_s=300.0)
    np.testing.assert_array_equal(g.people["Ada"].embeddings[0], vec(1))
    g.enrol("Ada", [vec(9)], now_s=300.0, replace=True)
    np.testing.assert_array_equal(g.people["Ada"].embeddings, vec(9)[None])


@pytest.mark.parametrize("vectors", [[], [vec(1)] * (gal.MAX_EMBEDDINGS + 1),
                                     [np.ones(DIM, np.float32)], [vec(1)[:10]]])
def test_bad_embeddings_are_refused(vectors: list[np.ndarray]) -> None:
    with pytest.raises(ValueError):
        gal.Gallery(MODEL).enrol("Ada", vectors, now_s=0.0)


def test_the_gallery_is_bounded(tmp_path: Path) -> None:
    g = gal.Gallery(MODEL)
    one = [vec(1)]
    for i in range(gal.MAX_PEOPLE):
        g.enrol(f"p{i}", one, now_s=0.0)
    with pytest.raises(gal.BadName, match="full"):
        g.enrol("one more", one, now_s=0.0)
    g.enrol("p0", [vec(2)], now_s=0.0, replace=True)  # retaking someone is still allowed
    gal.save(tmp_path / "g.bin", g, key())
    assert len(gal.load(tmp_path / "g.bin", MODEL, key()).people) == gal.MAX_PEOPLE


def test_forget_one_and_all(path: Path) -> None:
    g = gal.load(path, MODEL, key())
    assert g.forget(" Ada ") and not g.forget("Ada") and not g.forget("nobody")
    assert list(g.people) == ["Bob"]
    assert g.forget_all() == 1 and g.forget_all() == 0
    gal.save(path, g, key())
    assert gal.load(path, MODEL, key()).people == {}


def test_retention_forgets_people_not_seen_for_n_days() -> None:
    g = two_people()  # Ada seen at 100 s, Bob at 200 s
    g.seen("Ada", 100.0 + 5 * gal.DAY_S)
    g.seen("nobody", 1e9)  # not enrolled: nothing happens
    assert g.expire(200.0 + 3 * gal.DAY_S, days=3) == []
    assert g.expire(200.0 + 3 * gal.DAY_S + 1, days=3) == ["Bob"]
    assert list(g.people) == ["Ada"]
    with pytest.raises(ValueError):
        g.expire(0.0, days=0)
