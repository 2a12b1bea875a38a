"""The HiLink command envelope shared by the LD2410 and the LD2450 (pure, no I/O).

Both sensors take configuration commands in the same frame,
`FD FC FB FA | length (2) | command word (2) | value | 04 03 02 01`, and
answer with the same ACK (`word | 0x0100`, a status word, data), inside
enable configuration (0x00FF) ... end configuration (0x00FE). The words
both models share (firmware, baud rate, factory reset, restart,
Bluetooth, MAC) and their ACK layouts live here once; each model's module
adds its own words. Checked against both HiLink protocol documents and
ESPHome's ld2410/ld2450 components (docs/radar.md, "what was checked").
All multi-byte fields are little-endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

COMMAND_HEAD = b"\xfd\xfc\xfb\xfa"
COMMAND_TAIL = b"\x04\x03\x02\x01"
ACK_FLAG = 0x0100
MAX_COMMAND_LENGTH = 64
"""Longest command/ACK payload accepted; longer is a false header (the longest
real one, the LD2450's zone ACK, is 30 bytes)."""

CMD_READ_FIRMWARE = 0x00A0
CMD_SET_BAUD_RATE = 0x00A1
CMD_FACTORY_RESET = 0x00A2
CMD_RESTART = 0x00A3
CMD_BLUETOOTH = 0x00A4
CMD_READ_MAC = 0x00A5
CMD_END_CONFIG = 0x00FE
CMD_ENABLE_CONFIG = 0x00FF

SHARED_COMMAND_NAMES: dict[int, str] = {
    CMD_READ_FIRMWARE: "read firmware version",
    CMD_SET_BAUD_RATE: "set baud rate",
    CMD_FACTORY_RESET: "factory reset",
    CMD_RESTART: "restart",
    CMD_BLUETOOTH: "bluetooth on/off",
    CMD_READ_MAC: "read MAC address",
    CMD_END_CONFIG: "end configuration",
    CMD_ENABLE_CONFIG: "enable configuration",
}

BAUD_RATES: dict[int, int] = {
    9600: 1, 19200: 2, 38400: 3, 57600: 4, 115200: 5, 230400: 6, 256000: 7, 460800: 8,
}
"""Baud rate -> the index the sensor wants (0x00A1); the same table on both models."""


class ProtocolError(ValueError):
    """Bytes that do not form what the protocol says they must."""


@dataclass(frozen=True, slots=True)
class Ack:
    """A command ACK: the command word it answers, status (0 = success), data."""

    command: int
    status: int
    data: bytes = b""

    @property
    def ok(self) -> bool:
        return self.status == 0


@dataclass(frozen=True, slots=True)
class Command:
    """A command frame as the sensor receives it (used by the simulators)."""

    command: int
    value: bytes = b""


@dataclass(frozen=True, slots=True)
class EnableInfo:
    protocol_version: int
    buffer_size: int


# --- encoders ----------------------------------------------------------------------


def encode_command(command: int, value: bytes = b"") -> bytes:
    """A host->sensor command frame: head, length, word, value, tail."""
    body = struct.pack("<H", command) + value
    return COMMAND_HEAD + struct.pack("<H", len(body)) + body + COMMAND_TAIL


def encode_ack(command: int, status: int = 0, data: bytes = b"") -> bytes:
    """A sensor->host ACK frame for `command` (the simulators' answer)."""
    body = struct.pack("<HH", command | ACK_FLAG, status) + data
    return COMMAND_HEAD + struct.pack("<H", len(body)) + body + COMMAND_TAIL


def enable_config() -> bytes:
    return encode_command(CMD_ENABLE_CONFIG, struct.pack("<H", 1))


def end_config() -> bytes:
    return encode_command(CMD_END_CONFIG)


def read_firmware() -> bytes:
    return encode_command(CMD_READ_FIRMWARE)


def set_baud_rate(baud: int) -> bytes:
    if baud not in BAUD_RATES:
        raise ProtocolError(f"unsupported baud rate {baud}; one of {sorted(BAUD_RATES)}")
    return encode_command(CMD_SET_BAUD_RATE, struct.pack("<H", BAUD_RATES[baud]))


def factory_reset() -> bytes:
    return encode_command(CMD_FACTORY_RESET)


def restart() -> bytes:
    return encode_command(CMD_RESTART)


def bluetooth(on: bool) -> bytes:
    return encode_command(CMD_BLUETOOTH, struct.pack("<H", 1 if on else 0))


def read_mac() -> bytes:
    return encode_command(CMD_READ_MAC, struct.pack("<H", 1))


# --- ACK data ----------------------------------------------------------------------


def need(data: bytes, n: int, what: str) -> None:
    """ProtocolError unless the ACK data has at least `n` bytes."""
    if len(data) < n:
        raise ProtocolError(f"{what}: ACK data has {len(data)} bytes, need {n}")


def decode_enable(data: bytes) -> EnableInfo:
    need(data, 4, "enable configuration")
    version, size = struct.unpack_from("<HH", data)
    return EnableInfo(version, size)


def encode_firmware(firmware_type: int, major: int, minor: int) -> bytes:
    return struct.pack("<HHI", firmware_type, major, minor)


def decode_firmware(data: bytes) -> str:
    """`V1.07.22091615`: major word 0x0107 -> 1.07, minor dword printed in hex."""
    need(data, 8, "read firmware version")
    _type, major, minor = struct.unpack_from("<HHI", data)
    return f"V{major >> 8}.{major & 0xFF:02x}.{minor:08x}"


def decode_mac(data: bytes) -> str:
    need(data, 6, "read MAC address")
    return ":".join(f"{b:02x}" for b in data[:6])


def decode_command_payload(payload: bytes) -> Ack | Command:
    """A command frame's payload (between length and tail) -> Ack or Command."""
    if len(payload) < 2:
        raise ProtocolError("short command")
    (word,) = struct.unpack_from("<H", payload)
    if word & ACK_FLAG:
        if len(payload) < 4:
            raise ProtocolError("short ACK")
        (status,) = struct.unpack_from("<H", payload, 2)
        return Ack(word & ~ACK_FLAG, status, bytes(payload[4:]))
    return Command(word, bytes(payload[2:]))


@dataclass
class ParserStats:
    """Counters a driver reports in diagnostics (both models' parsers keep them).

    `intact_frames` counts every frame whose framing was sound (reports,
    ACKs, commands and `unusual_frames`: well-formed reports with content
    we do not know, such as a future target state). A driver takes any of
    them as a sign that the line works: a sensor in an unusual mode is not
    a wedged adapter.
    """

    reports: int = 0
    acks: int = 0
    commands: int = 0
    bad_frames: int = 0
    unusual_frames: int = 0
    intact_frames: int = 0
    skipped_bytes: int = 0
    last_error: str = ""
    errors: dict[str, int] = field(default_factory=dict)

    def bad(self, why: str) -> None:
        """Count a rejected frame and why (reasons are ours, but stay bounded)."""
        self.bad_frames += 1
        self.last_error = why
        if why in self.errors or len(self.errors) < 32:
            self.errors[why] = self.errors.get(why, 0) + 1
