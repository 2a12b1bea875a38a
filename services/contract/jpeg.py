"""JPEG files: the size read from the header before anything is decoded, and
bgr8 frames compressed into them; written once for the camera, the
dashboard and the recordings.

A decoder allocates the whole frame its header announces: a 700-byte file
that claims 20000x20000 pixels makes OpenCV allocate 1.2 GB and spend
seconds filling it. So the face detector reads the frame header (the SOF
marker segment) first and refuses oversized or inconsistent files before
`cv2.imdecode` sees them; a replayed recording's images get their size the
same way.

The walk is strict on purpose: from SOI, marker segment after marker
segment by their lengths, until the first SOF. Anything else (garbage
between segments, a scan or EOI before the frame header, a truncated
segment) is refused, so a file accepted here has exactly the frame header
libjpeg will use. Reading the header is pure; compressing imports OpenCV
when first asked, so a process that never compresses never loads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from buddybot.contract import messages as m

if TYPE_CHECKING:
    import numpy as np

SOI, EOI, SOS = 0xD8, 0xD9, 0xDA
SOF_MARKERS = frozenset({0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7,
                         0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF})
"""Start-of-frame codes; C4 (DHT), C8 (reserved) and CC (DAC) are not frame headers."""
PROGRESSIVE = frozenset({0xC2, 0xC6, 0xCA, 0xCE})
STANDALONE = frozenset({0x01, *range(0xD0, 0xD8)})
"""TEM and RST0..7 carry no length field."""


class JpegError(ValueError):
    """The bytes are not a JPEG whose frame header can be trusted."""


class PixelsError(ValueError):
    """A bgr8 image whose data is not the width x height x 3 bytes it says."""


@dataclass(frozen=True)
class JpegHeader:
    """What the frame header (SOF) says about the image."""

    width: int
    height: int
    components: int
    """1 grey, 3 YCbCr/RGB, 4 CMYK/YCCK."""
    progressive: bool
    marker: int

    @property
    def pixels(self) -> int:
        return self.width * self.height


def _u16(data: bytes | memoryview, pos: int) -> int:
    return (data[pos] << 8) | data[pos + 1]


def read_header(data: bytes | memoryview) -> JpegHeader:
    """The frame header of a JPEG file; raises `JpegError` saying what is wrong."""
    n = len(data)
    if n < 2 or data[0] != 0xFF or data[1] != SOI:
        raise JpegError("not a JPEG (does not start with the SOI marker)")
    pos = 2
    while True:
        if pos >= n:
            raise JpegError("truncated before the frame header (no SOF marker)")
        if data[pos] != 0xFF:
            raise JpegError(f"byte {pos}: expected a marker, found 0x{data[pos]:02x}")
        while pos < n and data[pos] == 0xFF:  # 0xFF fill bytes may precede a marker code
            pos += 1
        if pos >= n:
            raise JpegError("truncated inside a marker")
        code = data[pos]
        pos += 1
        if code in STANDALONE:
            continue
        if code == EOI:
            raise JpegError("end of image before a frame header (no SOF marker)")
        if code == SOS:
            raise JpegError("scan data before a frame header (no SOF marker)")
        if code in (0x00, SOI):
            raise JpegError(f"byte {pos - 1}: invalid marker 0xff{code:02x}")
        if pos + 2 > n:
            raise JpegError(f"truncated in the length of marker 0xff{code:02x}")
        length = _u16(data, pos)
        if length < 2 or pos + length > n:
            raise JpegError(f"marker 0xff{code:02x}: length {length} does not fit the "
                            f"{n} bytes")
        if code in SOF_MARKERS:
            return _frame_header(data, pos, length, code)
        pos += length


def _frame_header(data: bytes | memoryview, pos: int, length: int, code: int) -> JpegHeader:
    """Decode an SOF segment: length(2) precision(1) height(2) width(2) components(1) ..."""
    if length < 8:
        raise JpegError(f"frame header of {length} bytes is too short")
    height, width, components = _u16(data, pos + 3), _u16(data, pos + 5), data[pos + 7]
    if width == 0 or height == 0:
        raise JpegError(f"frame header says {width}x{height} (a height defined later by a "
                        "DNL marker is not supported)")
    if components not in (1, 3, 4):
        raise JpegError(f"frame header has {components} colour components (1, 3 or 4 "
                        "expected)")
    if length < 8 + 3 * components:
        raise JpegError(f"frame header of {length} bytes is too short for {components} "
                        "components")
    return JpegHeader(width, height, components, code in PROGRESSIVE, code)


# --- compressing ----------------------------------------------------------------------


def encode(bgr: np.ndarray, quality: int) -> bytes | None:
    """A bgr8 frame (height x width x 3 bytes) as a JPEG file of `quality` (1-100);
    None when OpenCV refuses the frame."""
    import cv2

    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    return buf.tobytes() if ok else None


def from_image(image: m.Image, quality: int) -> bytes | None:
    """An `Image` message as a JPEG file: `jpeg` passes through untouched, `bgr8`
    is compressed (None when OpenCV refuses it). Raises `PixelsError` when the
    bgr8 data does not hold the size the message states."""
    if image.encoding == "jpeg":
        return image.data
    import numpy as np

    expected = image.width * image.height * 3
    if len(image.data) != expected:
        raise PixelsError(f"bgr8 image {image.width}x{image.height} needs {expected} bytes, "
                          f"has {len(image.data)}")
    return encode(np.frombuffer(image.data, np.uint8).reshape(image.height, image.width, 3),
                  quality)
