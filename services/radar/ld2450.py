"""The HiLink LD2450 serial protocol, as pure functions and an incremental parser.

No I/O here: bytes in, typed frames out (and the reverse for commands), so
every rule is unit-tested without a serial port. The layouts follow
HiLink's "HLK-LD2450 serial communication protocol" and were checked
against ESPHome's ld2450 component (docs/radar.md, "what was checked").

A report frame is 30 bytes, `AA FF 03 00 | 3 x 8-byte slot | 55 CC`, sent
about 10 times a second. A slot is four little-endian words: x (mm), y
(mm), speed (cm/s) and the distance resolution (mm). x, y and speed are
SIGN-MAGNITUDE: bit 15 set means positive, clear means negative, the other
15 bits the magnitude (decoding them as two's complement puts a person on
the wrong side). An empty slot is all zeros. The zone rectangles of the
zone filter commands (0x00C1/0x00C2), by contrast, are plain two's
complement int16, as the protocol document's example and ESPHome agree.

Commands use the LD2410's envelope (`envelope.py`). The parser never
trusts a frame: the head, the fixed length and the `55 CC` end are
checked; a bad frame is dropped and counted, and scanning restarts one
byte after the rejected head, so garbage costs at most that frame. It runs
in time linear in its input however the input is chunked, and its buffer
never holds more than one frame plus a chunk.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from buddybot.radar.envelope import (
    COMMAND_HEAD,
    COMMAND_TAIL,
    MAX_COMMAND_LENGTH,
    SHARED_COMMAND_NAMES,
    Ack,
    Command,
    ParserStats,
    ProtocolError,
    decode_command_payload,
    encode_command,
    need,
)

REPORT_HEAD = b"\xaa\xff\x03\x00"
REPORT_END = b"\x55\xcc"
SLOTS = 3
SLOT_SIZE = 8
REPORT_SIZE = len(REPORT_HEAD) + SLOTS * SLOT_SIZE + len(REPORT_END)  # 30

MAGNITUDE_MAX = 0x7FFF
"""Largest magnitude a sign-magnitude word carries (mm or cm/s)."""

# The sensor's documented field of view: beyond it a value is implausible.
X_LIMIT_MM = 4000
Y_LIMIT_MM = 8000

# Command words (HiLink's LD2450 protocol document).
CMD_SINGLE_TARGET = 0x0080
CMD_MULTI_TARGET = 0x0090
CMD_QUERY_TRACKING_MODE = 0x0091
CMD_QUERY_ZONE_FILTER = 0x00C1
CMD_SET_ZONE_FILTER = 0x00C2

COMMAND_NAMES: dict[int, str] = {
    CMD_SINGLE_TARGET: "single target tracking",
    CMD_MULTI_TARGET: "multi target tracking",
    CMD_QUERY_TRACKING_MODE: "query target tracking mode",
    CMD_QUERY_ZONE_FILTER: "query zone filtering",
    CMD_SET_ZONE_FILTER: "set zone filtering",
    **SHARED_COMMAND_NAMES,
}

TRACKING_MODES: dict[int, str] = {1: "single", 2: "multi"}
"""What 0x0091 answers -> our name for it."""

ZONE_OFF, ZONE_DETECT_ONLY, ZONE_IGNORE = 0, 1, 2
ZONE_MODES: dict[int, str] = {ZONE_OFF: "off", ZONE_DETECT_ONLY: "detect-only-inside",
                              ZONE_IGNORE: "ignore-inside"}
ZONES = 3
INT16_MIN, INT16_MAX = -0x8000, 0x7FFF

BLUETOOTH_OFF_MAC = "08:05:04:03:02:01"
"""What 0x00A5 answers while Bluetooth is off (ESPHome reads it so too)."""


# --- frames ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Target:
    """One slot's target, decoded: mm, mm, cm/s (+ = moving away), mm."""

    x_mm: int
    y_mm: int
    speed_cms: int
    resolution_mm: int

    def plausible(self) -> bool:
        """Inside the sensor's documented field (x +-4000 mm, y 0..8000 mm)."""
        return abs(self.x_mm) <= X_LIMIT_MM and 0 <= self.y_mm <= Y_LIMIT_MM


@dataclass(frozen=True, slots=True)
class Report:
    """One report: per slot a Target, or None for an empty slot."""

    slots: tuple[Target | None, ...]

    def targets(self) -> list[tuple[int, Target]]:
        """(slot, target) of every occupied slot."""
        return [(i, t) for i, t in enumerate(self.slots) if t is not None]


Frame = Report | Ack | Command


def decode_sign_magnitude(word: int) -> int:
    """Bit 15 set: +magnitude; clear: -magnitude (0x0000 and 0x8000 are both 0)."""
    magnitude = word & MAGNITUDE_MAX
    return magnitude if word & 0x8000 else -magnitude


def encode_sign_magnitude(value: int) -> int:
    """The word for `value`; 0 is sent as 0x0000, as an empty slot has it."""
    if abs(value) > MAGNITUDE_MAX:
        raise ProtocolError(f"{value} does not fit a sign-magnitude word (|v| <= 32767)")
    return (0x8000 | value) if value > 0 else -value


def _decode_slot(data: bytes | bytearray, offset: int) -> Target | None:
    xw, yw, sw, res = struct.unpack_from("<HHHH", data, offset)
    x, y = decode_sign_magnitude(xw), decode_sign_magnitude(yw)
    if x == 0 and y == 0:
        return None  # an all-zero slot; a "target" on the sensor itself is no person
    return Target(x, y, decode_sign_magnitude(sw), res)


def decode_report(frame: bytes | bytearray) -> Report:
    """A whole 30-byte report frame -> Report, or ProtocolError."""
    if len(frame) != REPORT_SIZE:
        raise ProtocolError(f"report must be {REPORT_SIZE} bytes, got {len(frame)}")
    if frame[:4] != REPORT_HEAD:
        raise ProtocolError("bad report head")
    if frame[-2:] != REPORT_END:
        raise ProtocolError("bad 0x55 0xCC end")
    return Report(tuple(_decode_slot(frame, 4 + SLOT_SIZE * i) for i in range(SLOTS)))


def encode_report(report: Report) -> bytes:
    """The report frame's bytes exactly as a sensor sends them (simulator, tests)."""
    if len(report.slots) != SLOTS:
        raise ProtocolError(f"a report has {SLOTS} slots, got {len(report.slots)}")
    body = bytearray()
    for target in report.slots:
        if target is None:
            body += bytes(SLOT_SIZE)
            continue
        if not 0 <= target.resolution_mm <= 0xFFFF:
            raise ProtocolError(f"resolution {target.resolution_mm} mm is not a uint16")
        body += struct.pack("<HHHH", encode_sign_magnitude(target.x_mm),
                            encode_sign_magnitude(target.y_mm),
                            encode_sign_magnitude(target.speed_cms), target.resolution_mm)
    return REPORT_HEAD + bytes(body) + REPORT_END


# --- commands ----------------------------------------------------------------------


def single_target() -> bytes:
    """0x0080: track one target (slots 2 and 3 stay empty)."""
    return encode_command(CMD_SINGLE_TARGET)


def multi_target() -> bytes:
    """0x0090: track up to three targets (the factory setting)."""
    return encode_command(CMD_MULTI_TARGET)


def query_tracking_mode() -> bytes:
    return encode_command(CMD_QUERY_TRACKING_MODE)


def decode_tracking_mode(data: bytes) -> str:
    """0x0091's ACK data: word 1 -> "single", 2 -> "multi"."""
    need(data, 2, "query target tracking mode")
    (mode,) = struct.unpack_from("<H", data)
    if mode not in TRACKING_MODES:
        raise ProtocolError(f"query target tracking mode: unknown mode {mode}")
    return TRACKING_MODES[mode]


@dataclass(frozen=True, slots=True)
class Zone:
    """A rectangle in the sensor's x/y (mm) by two diagonal corners."""

    x1: int
    y1: int
    x2: int
    y2: int


EMPTY_ZONE = Zone(0, 0, 0, 0)


@dataclass(frozen=True, slots=True)
class ZoneFilter:
    """Mode 0 off, 1 detect only inside the zones, 2 ignore inside; three rectangles."""

    mode: int
    zones: tuple[Zone, ...] = (EMPTY_ZONE,) * ZONES

    @property
    def mode_name(self) -> str:
        return ZONE_MODES.get(self.mode, f"unknown ({self.mode})")


def encode_zone_filter(zf: ZoneFilter) -> bytes:
    """The 26 bytes of 0x00C2's value and of 0x00C1's ACK data."""
    if zf.mode not in ZONE_MODES:
        raise ProtocolError(f"zone mode must be 0 (off), 1 (detect only inside) or "
                            f"2 (ignore inside), got {zf.mode}")
    if len(zf.zones) != ZONES:
        raise ProtocolError(f"zone filtering takes {ZONES} rectangles, got {len(zf.zones)}")
    values = [v for z in zf.zones for v in (z.x1, z.y1, z.x2, z.y2)]
    if any(not INT16_MIN <= v <= INT16_MAX for v in values):
        raise ProtocolError("zone corners must be -32768..32767 mm")
    return struct.pack("<H12h", zf.mode, *values)


def set_zone_filter(zf: ZoneFilter) -> bytes:
    """0x00C2: set the mode and the three rectangles (unused ones: all zero)."""
    return encode_command(CMD_SET_ZONE_FILTER, encode_zone_filter(zf))


def query_zone_filter() -> bytes:
    return encode_command(CMD_QUERY_ZONE_FILTER)


def decode_zone_filter(data: bytes) -> ZoneFilter:
    need(data, 26, "query zone filtering")
    mode, *values = struct.unpack_from("<H12h", data)
    if mode not in ZONE_MODES:
        raise ProtocolError(f"query zone filtering: unknown mode {mode}")
    zones = tuple(Zone(*values[4 * i:4 * i + 4]) for i in range(ZONES))
    return ZoneFilter(mode, zones)


# --- the incremental parser --------------------------------------------------------


class Parser:
    """Feed arbitrary chunks with `feed()`; get every complete valid frame back.

    The same scheme as the LD2410 parser: the next header of each kind is
    found once with `bytearray.find` and remembered until the scan passes
    it (linear time), bytes that cannot start a frame are discarded and
    counted in `skipped_bytes`, at most 3 bytes of a possible partial
    header are kept between chunks.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.stats = ParserStats()

    def reset(self) -> None:
        """Forget a partial frame (after a reconnect the stream restarts)."""
        self._buf.clear()

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[Frame]:
        buf = self._buf
        buf += chunk
        out: list[Frame] = []
        stats = self.stats
        pos = 0
        end = len(buf)
        r = c = -2  # next report/command header at or after pos (-1: none; -2: not searched)
        while True:
            if r != -1 and r < pos:
                r = buf.find(REPORT_HEAD, pos)
            if c != -1 and c < pos:
                c = buf.find(COMMAND_HEAD, pos)
            if r < 0 and c < 0:
                keep = max(pos, end - 3)
                while keep < end and buf[keep] not in (0xAA, 0xFD):
                    keep += 1
                stats.skipped_bytes += keep - pos
                pos = keep
                break
            start = r if c < 0 or (0 <= r < c) else c
            stats.skipped_bytes += start - pos
            pos = start
            if start == r:
                frame_end = start + REPORT_SIZE
                if frame_end > end:
                    break
                if buf[frame_end - 2:frame_end] != REPORT_END:
                    stats.bad("bad 0x55 0xCC end")
                    pos = start + 1
                    continue
                frame: Frame = decode_report(buf[start:frame_end])
                stats.reports += 1
            else:
                if end - start < 6:
                    break
                (length,) = struct.unpack_from("<H", buf, start + 4)
                if length > MAX_COMMAND_LENGTH:
                    stats.bad("length too large")
                    pos = start + 1
                    continue
                frame_end = start + 6 + length + 4
                if frame_end > end:
                    break
                if buf[frame_end - 4:frame_end] != COMMAND_TAIL:
                    stats.bad("bad tail")
                    pos = start + 1
                    continue
                try:
                    frame = decode_command_payload(bytes(buf[start + 6:frame_end - 4]))
                except ProtocolError as exc:
                    stats.bad(str(exc))
                    pos = start + 1
                    continue
                if isinstance(frame, Ack):
                    stats.acks += 1
                else:
                    stats.commands += 1
            stats.intact_frames += 1
            out.append(frame)
            pos = frame_end
        del buf[:pos]
        return out
