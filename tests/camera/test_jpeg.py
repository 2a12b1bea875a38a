"""The JPEG frame-header reader (pure) on real files and on crafted ones."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image as PilImage

from buddybot.camera import jpeg
from buddybot.camera.sim import face_path
from tests.camera import jpegs

DATA = Path(__file__).parent / "data"
REAL = [DATA / "grace_hopper.jpg", face_path()]


@pytest.mark.parametrize("path", REAL, ids=lambda p: p.name)
def test_real_files_give_the_size_opencv_decodes(path: Path) -> None:
    header = jpeg.read_header(path.read_bytes())
    h, w = cv2.imread(str(path)).shape[:2]
    assert (header.width, header.height, header.components) == (w, h, 3)
    assert not header.progressive and header.pixels == w * h


def test_progressive_grey_and_cmyk_files() -> None:
    photo = cv2.imread(str(DATA / "grace_hopper.jpg"))
    progressive = jpeg.read_header(jpegs.encode(photo, progressive=True))
    assert (progressive.width, progressive.height, progressive.progressive) == (512, 600, True)
    assert progressive.marker == 0xC2
    grey = jpeg.read_header(jpegs.encode(cv2.cvtColor(photo, cv2.COLOR_BGR2GRAY)))
    assert (grey.width, grey.height, grey.components) == (512, 600, 1)
    buf = _pil_jpeg(PilImage.new("CMYK", (33, 17), (10, 20, 30, 40)))
    assert jpeg.read_header(buf) == jpeg.JpegHeader(33, 17, 4, False, 0xC0)


def _pil_jpeg(img: PilImage.Image, **options: object) -> bytes:
    import io

    out = io.BytesIO()
    img.save(out, "JPEG", **options)
    return out.getvalue()


def test_metadata_segments_before_the_frame_header_are_skipped() -> None:
    """EXIF (with its own thumbnail), a comment and 0xFF fill bytes come first."""
    photo = PilImage.open(DATA / "grace_hopper.jpg")
    exif = PilImage.Exif()
    exif[0x010E] = "x" * 3000  # ImageDescription: a long APP1 segment
    data = _pil_jpeg(photo, exif=exif.tobytes(), comment=b"a comment")
    assert b"Exif" in data[:64]
    padded = data[:2] + b"\xff\xff\xff" + data[2:]  # fill bytes before the first marker
    for buf in (data, padded):
        header = jpeg.read_header(buf)
        assert (header.width, header.height) == (512, 600)


def test_huge_dimensions_are_read_without_decoding() -> None:
    bomb = jpegs.bomb(20000, 20000)
    assert len(bomb) < 1000
    header = jpeg.read_header(bomb)
    assert (header.width, header.height) == (20000, 20000)
    assert header.pixels == 400_000_000


def test_every_truncation_is_refused_or_gives_the_true_size() -> None:
    data = (DATA / "grace_hopper.jpg").read_bytes()
    sof_end = jpegs.sof_offset(data) + 2 + 17  # SOF segment of 3 components: 17 bytes
    for n in range(sof_end + 1):
        cut = data[:n]
        if n < sof_end:
            with pytest.raises(jpeg.JpegError):
                jpeg.read_header(cut)
        else:
            assert (jpeg.read_header(cut).width, jpeg.read_header(cut).height) == (512, 600)


@pytest.mark.parametrize(("data", "says"), [
    (b"", "SOI"),
    (b"\x89PNG\r\n\x1a\n" + b"\x00" * 32, "SOI"),
    (b"\xff\xd8\xff\xd9", "end of image"),
    (b"\xff\xd8\xff\xda\x00\x08" + b"\x00" * 6, "scan data"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF\x00" + b"\x00" * 9 + b"garbage", "expected a marker"),
    (b"\xff\xd8\xff\xe0\x00\x01", "length 1"),
    (b"\xff\xd8\xff\xe0\xff\xff" + b"\x00" * 10, "does not fit"),
    (b"\xff\xd8\xff\x00\x00\x10", "invalid marker"),
    (b"\xff\xd8\xff\xd8\x00\x10", "invalid marker"),
    (b"\xff\xd8\xff\xc0\x00\x0b\x08\x00\x00\x02\x00\x01\x01\x11\x00", "DNL"),
    (b"\xff\xd8\xff\xc0\x00\x0b\x08\x00\x10\x00\x10\x02\x01\x11\x00", "2 colour components"),
    (b"\xff\xd8\xff\xc0\x00\x0b\x08\x00\x10\x00\x10\x03\x01\x11\x00", "too short"),
    (b"\xff\xd8\xff\xc0\x00\x06\x08\x00\x10\x00", "too short"),
    (b"\xff\xd8\xff", "truncated"),
])
def test_crafted_headers_are_refused_with_a_reason(data: bytes, says: str) -> None:
    with pytest.raises(jpeg.JpegError, match=says):
        jpeg.read_header(data)


def test_markers_that_are_not_frame_headers_are_skipped() -> None:
    """DHT (C4), DAC (CC) and restart markers before the SOF are not mistaken for it."""
    sof = b"\xff\xc0\x00\x0b\x08\x00\x30\x00\x40\x01\x01\x11\x00"
    data = (b"\xff\xd8" + b"\xff\xc4\x00\x04\x00\x00" + b"\xff\xcc\x00\x04\x00\x00"
            + b"\xff\xd0" + sof)
    header = jpeg.read_header(data)
    assert (header.width, header.height, header.components) == (64, 48, 1)


def test_random_bytes_never_raise_anything_but_jpeg_error() -> None:
    rng = np.random.default_rng(3)
    real = (DATA / "grace_hopper.jpg").read_bytes()[:800]
    for _ in range(3000):
        data = bytearray(real)
        for at in rng.integers(2, len(data), 4):
            data[at] = int(rng.integers(0, 256))
        try:
            header = jpeg.read_header(bytes(data))
        except jpeg.JpegError:
            continue
        assert header.width > 0 and header.height > 0
