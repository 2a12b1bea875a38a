"""JPEG files (contract/jpeg.py): the frame-header reader on real, crafted and fuzzed
bytes, and bgr8 frames compressed into files that reader accepts."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image as PilImage

from buddybot.camera.sim import face_path
from buddybot.contract import jpeg
from buddybot.contract import messages as m
from tests.camera import jpegs
from tests.properties import examples

DATA = Path(__file__).parents[1] / "camera" / "data"
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


MARKERS = st.sampled_from([b"\xff\xc0", b"\xff\xc2", b"\xff\xc4", b"\xff\xd0", b"\xff\xd9",
                           b"\xff\xda", b"\xff\xe0", b"\xff\xff", b"\xff\x00", b"\x00\x0b"])


@settings(max_examples=examples(600))
@given(st.lists(st.one_of(MARKERS, st.binary(max_size=12)), max_size=12).map(b"".join))
def test_fuzzed_headers_raise_only_jpeg_error(body: bytes) -> None:
    """Whatever follows SOI, the reader refuses it with a reason or returns a
    header a decoder can trust the size of."""
    try:
        header = jpeg.read_header(b"\xff\xd8" + body)
    except jpeg.JpegError:
        return
    assert header.width > 0 and header.height > 0 and header.components in (1, 3, 4)
    assert header.marker in jpeg.SOF_MARKERS


@settings(max_examples=examples(40))
@given(st.integers(1, 70), st.integers(1, 70), st.integers(1, 100))
def test_an_encoded_frame_has_its_size_in_its_header(width: int, height: int,
                                                      quality: int) -> None:
    bgr = np.random.default_rng(width * height).integers(0, 255, (height, width, 3), np.uint8)
    data = jpeg.encode(bgr, quality)
    assert data is not None
    assert jpeg.read_header(data) == jpeg.JpegHeader(width, height, 3, False, 0xC0)


def _image(encoding: str, data: bytes, width: int = 4, height: int = 2) -> m.Image:
    return m.Image(stamp_ns=1, frame_id="c", width=width, height=height, encoding=encoding,
                   data=data)


def test_an_image_message_becomes_a_jpeg_file() -> None:
    compressed = jpeg.from_image(_image("bgr8", bytes(range(24))), 90)
    assert compressed is not None
    header = jpeg.read_header(compressed)
    assert (header.width, header.height) == (4, 2)
    assert jpeg.from_image(_image("jpeg", compressed), 10) is compressed  # passed through


@pytest.mark.parametrize("size", [0, 23, 25])
def test_a_bgr8_image_of_the_wrong_size_is_refused(size: int) -> None:
    with pytest.raises(jpeg.PixelsError, match=f"4x2 needs 24 bytes, has {size}"):
        jpeg.from_image(_image("bgr8", bytes(size)), 90)
