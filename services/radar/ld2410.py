"""The HiLink LD2410 serial protocol, as pure functions and an incremental parser.

No I/O here: bytes in, typed frames out (and the reverse for commands), so
every rule of the protocol is unit-tested without a serial port. Offsets
and words follow HiLink's HLK-LD2410 serial communication protocol
document (summarised in docs/radar.md). All multi-byte fields are little-endian.

Why our own parser: the Arduino LD2410 library of the original ROS 2 design reads distances as
one byte, drops frames containing `0x0A` and swaps moving/still fields.
Here every distance is 16-bit, bytes are bytes (nothing is line-based),
and each field is read from its documented offset.

The parser never trusts a frame: head, declared length, data type, the
`0xAA` head and `0x55 0x00` end markers and the tail are all checked; a
bad frame is dropped and counted, and scanning restarts one byte after
the rejected header, so a stray `F4 F3 F2 F1` inside data (or a partial
frame after a reconnect) costs at most that frame, never the stream.
It runs in time linear in its input, however the input is chunked: one
`feed()` of megabytes of garbage and frames costs the same per byte as
a live stream of 45-byte reads.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

# The shared envelope, re-exported: `ld2410.encode_command` etc. keep working.
from buddybot.radar.envelope import (
    ACK_FLAG,  # noqa: F401
    BAUD_RATES,  # noqa: F401
    CMD_BLUETOOTH,  # noqa: F401
    CMD_ENABLE_CONFIG,  # noqa: F401
    CMD_END_CONFIG,  # noqa: F401
    CMD_FACTORY_RESET,  # noqa: F401
    CMD_READ_FIRMWARE,  # noqa: F401
    CMD_READ_MAC,  # noqa: F401
    CMD_RESTART,  # noqa: F401
    CMD_SET_BAUD_RATE,  # noqa: F401
    COMMAND_HEAD,  # noqa: F401
    COMMAND_TAIL,  # noqa: F401
    MAX_COMMAND_LENGTH,  # noqa: F401
    SHARED_COMMAND_NAMES,
    Ack,
    Command,
    EnableInfo,  # noqa: F401
    FrameParser,
    NeedMore,
    ParserStats,  # noqa: F401
    ProtocolError,
    UnusualFrame,
    bluetooth,  # noqa: F401
    decode_command_payload,  # noqa: F401
    decode_enable,  # noqa: F401
    decode_firmware,  # noqa: F401
    decode_mac,  # noqa: F401
    enable_config,  # noqa: F401
    encode_ack,  # noqa: F401
    encode_command,
    encode_firmware,  # noqa: F401
    end_config,  # noqa: F401
    factory_reset,  # noqa: F401
    need,
    read_firmware,  # noqa: F401
    read_mac,  # noqa: F401
    restart,  # noqa: F401
    set_baud_rate,  # noqa: F401
)

REPORT_HEAD = b"\xf4\xf3\xf2\xf1"
REPORT_TAIL = b"\xf8\xf7\xf6\xf5"

TYPE_ENGINEERING = 0x01
TYPE_BASIC = 0x02
DATA_HEAD = 0xAA
DATA_END = b"\x55\x00"
BASIC_LENGTH = 0x000D
MAX_GATE = 8

# Target state byte: 0..3 = bit 0 moving, bit 1 still. LD2410C firmware
# sends 4..6 while it measures the room's background noise (0x000B): no
# target information in those frames, but they are valid frames.
STATE_NOISE_DETECTING = 4
STATE_NOISE_DETECTION_SUCCEEDED = 5
STATE_NOISE_DETECTION_FAILED = 6
MAX_TARGET_STATE = STATE_NOISE_DETECTION_FAILED

# Longest payloads we accept; anything longer is a false header (the real
# longest report is 35 bytes, the longest ACK, read parameters, 28 bytes).
MAX_REPORT_LENGTH = 13 + 2 * (MAX_GATE + 1) + 2 + 2

# Command words (HiLink's protocol document; 0x000B/0x001B and 0x00A8/0x00A9
# are LD2410C additions).
CMD_AUTO_THRESHOLDS = 0x000B
CMD_AUTO_THRESHOLDS_STATUS = 0x001B
CMD_SET_MAX_GATES = 0x0060
CMD_READ_PARAMETERS = 0x0061
CMD_ENGINEERING_ON = 0x0062
CMD_ENGINEERING_OFF = 0x0063
CMD_SET_SENSITIVITY = 0x0064
CMD_BLUETOOTH_AUTH = 0x00A8
CMD_BLUETOOTH_PASSWORD = 0x00A9
CMD_SET_RESOLUTION = 0x00AA
CMD_READ_RESOLUTION = 0x00AB
CMD_SET_LIGHT_CONTROL = 0x00AD
CMD_READ_LIGHT_CONTROL = 0x00AE

COMMAND_NAMES: dict[int, str] = {
    CMD_AUTO_THRESHOLDS: "start background noise detection (auto thresholds)",
    CMD_AUTO_THRESHOLDS_STATUS: "query background noise detection",
    CMD_SET_MAX_GATES: "set max gates / no-one duration",
    CMD_READ_PARAMETERS: "read parameters",
    CMD_ENGINEERING_ON: "engineering mode on",
    CMD_ENGINEERING_OFF: "engineering mode off",
    CMD_SET_SENSITIVITY: "set gate sensitivity",
    CMD_BLUETOOTH_AUTH: "bluetooth authentication (get permissions)",
    CMD_BLUETOOTH_PASSWORD: "set bluetooth password",
    CMD_SET_RESOLUTION: "set distance resolution",
    CMD_READ_RESOLUTION: "read distance resolution",
    CMD_SET_LIGHT_CONTROL: "set light / OUT control",
    CMD_READ_LIGHT_CONTROL: "read light / OUT control",
    **SHARED_COMMAND_NAMES,
}

RESOLUTIONS: dict[int, float] = {0: 0.75, 1: 0.20}
"""Distance-resolution index (0x00AA/0x00AB) -> metres per gate."""

NOISE_DETECTION_STATUS: dict[int, str] = {0: "not started", 1: "in progress", 2: "completed"}
"""What 0x001B answers: the state of the background noise detection."""

BLUETOOTH_PASSWORD_LENGTH = 6
"""The Bluetooth password is exactly 6 ASCII characters (factory: "HiLink")."""


# --- frames ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Report:
    """One report frame. Distances in cm (16-bit), energies as sent (0..255).

    `light_level`/`out_pin` are the two optional bytes after the gate
    energies, as sent: only firmware V2.x defines them as light level and
    OUT pin (V1.07 sends two other bytes there), so what they mean is for
    the reader who knows the firmware to decide (`convert.py`).
    """

    target_state: int
    moving_distance: int
    moving_energy: int
    still_distance: int
    still_energy: int
    detection_distance: int
    engineering: bool = False
    max_moving_gate: int | None = None
    max_still_gate: int | None = None
    moving_gate_energy: tuple[int, ...] | None = None
    still_gate_energy: tuple[int, ...] | None = None
    light_level: int | None = None
    out_pin: int | None = None


Frame = Report | Ack | Command


# --- encoders ----------------------------------------------------------------------


def encode_report(report: Report) -> bytes:
    """The report frame's bytes (basic or engineering), exactly as a sensor sends it."""
    target = struct.pack(
        "<BHBHBH", report.target_state, report.moving_distance, report.moving_energy,
        report.still_distance, report.still_energy, report.detection_distance,
    )
    if not report.engineering:
        payload = bytes((TYPE_BASIC, DATA_HEAD)) + target + DATA_END
    else:
        moving = report.moving_gate_energy or ()
        still = report.still_gate_energy or ()
        n_moving = report.max_moving_gate if report.max_moving_gate is not None else MAX_GATE
        n_still = report.max_still_gate if report.max_still_gate is not None else MAX_GATE
        if len(moving) != n_moving + 1 or len(still) != n_still + 1:
            raise ProtocolError("engineering report needs N+1 energies per gate table")
        extra = b""
        if report.light_level is not None or report.out_pin is not None:
            extra = bytes((report.light_level or 0, report.out_pin or 0))
        payload = (bytes((TYPE_ENGINEERING, DATA_HEAD)) + target + bytes((n_moving, n_still))
                   + bytes(moving) + bytes(still) + extra + DATA_END)
    return REPORT_HEAD + struct.pack("<H", len(payload)) + payload + REPORT_TAIL


def set_max_gates(moving_gate: int, still_gate: int, no_one_duration_s: int) -> bytes:
    """0x0060: farthest moving/still gate (2..8) and the no-one duration (0..65535 s)."""
    if not (2 <= moving_gate <= MAX_GATE and 2 <= still_gate <= MAX_GATE):
        raise ProtocolError(f"max gates must be 2..{MAX_GATE}, got {moving_gate}/{still_gate}")
    if not 0 <= no_one_duration_s <= 0xFFFF:
        raise ProtocolError(f"no-one duration must be 0..65535 s, got {no_one_duration_s}")
    value = struct.pack("<HIHIHI", 0, moving_gate, 1, still_gate, 2, no_one_duration_s)
    return encode_command(CMD_SET_MAX_GATES, value)


def read_parameters() -> bytes:
    return encode_command(CMD_READ_PARAMETERS)


def engineering_mode(on: bool) -> bytes:
    return encode_command(CMD_ENGINEERING_ON if on else CMD_ENGINEERING_OFF)


def set_gate_sensitivity(gate: int | None, moving: int, still: int) -> bytes:
    """0x0064: sensitivity 0..100 of one gate (0..8) or of all gates (gate None)."""
    if gate is not None and not 0 <= gate <= MAX_GATE:
        raise ProtocolError(f"gate must be 0..{MAX_GATE}, got {gate}")
    if not (0 <= moving <= 100 and 0 <= still <= 100):
        raise ProtocolError(f"sensitivities must be 0..100, got {moving}/{still}")
    gate_value = 0xFFFF if gate is None else gate
    value = struct.pack("<HIHIHI", 0, gate_value, 1, moving, 2, still)
    return encode_command(CMD_SET_SENSITIVITY, value)


def start_auto_thresholds(duration_s: int) -> bytes:
    """0x000B (LD2410C): measure the room's background noise for `duration_s`
    seconds and set every gate's threshold from it. Reports carry target
    states 4..6 while it runs and when it ends."""
    if not 1 <= duration_s <= 0xFFFF:
        raise ProtocolError(f"noise detection duration must be 1..65535 s, got {duration_s}")
    return encode_command(CMD_AUTO_THRESHOLDS, struct.pack("<H", duration_s))


def query_auto_thresholds() -> bytes:
    """0x001B (LD2410C): the state of the background noise detection."""
    return encode_command(CMD_AUTO_THRESHOLDS_STATUS)


def _password(password: str) -> bytes:
    raw = password.encode("ascii", "replace")
    if (len(password) != BLUETOOTH_PASSWORD_LENGTH or not password.isascii()
            or not password.isprintable()):
        raise ProtocolError(f"bluetooth password must be {BLUETOOTH_PASSWORD_LENGTH} "
                            "printable ASCII characters")
    return raw


def bluetooth_auth(password: str) -> bytes:
    """0x00A8 (LD2410C): "obtain Bluetooth permissions" with the password.
    The module accepts it over Bluetooth; over serial it may refuse it."""
    return encode_command(CMD_BLUETOOTH_AUTH, _password(password))


def set_bluetooth_password(password: str) -> bytes:
    """0x00A9 (LD2410C): the new 6-character Bluetooth password (effective after restart)."""
    return encode_command(CMD_BLUETOOTH_PASSWORD, _password(password))


def resolution_index(metres_per_gate: float) -> int:
    for index, metres in RESOLUTIONS.items():
        if abs(metres - metres_per_gate) < 1e-6:
            return index
    raise ProtocolError(f"resolution must be 0.75 or 0.2 m per gate, got {metres_per_gate}")


def set_resolution(metres_per_gate: float) -> bytes:
    return encode_command(CMD_SET_RESOLUTION, struct.pack("<H", resolution_index(metres_per_gate)))


def read_resolution() -> bytes:
    return encode_command(CMD_READ_RESOLUTION)


def set_light_control(function: int, threshold: int, out_level: int) -> bytes:
    """0x00AD: light function (0 off, 1 below, 2 above threshold), threshold, OUT level."""
    if function not in (0, 1, 2) or not 0 <= threshold <= 255 or out_level not in (0, 1):
        raise ProtocolError("light control: function 0..2, threshold 0..255, OUT level 0/1")
    return encode_command(CMD_SET_LIGHT_CONTROL, bytes((function, threshold, out_level, 0)))


def read_light_control() -> bytes:
    return encode_command(CMD_READ_LIGHT_CONTROL)


# --- ACK data decoders -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Parameters:
    """What 0x0061 returns: gates, per-gate sensitivities, no-one duration."""

    max_gate: int
    max_moving_gate: int
    max_still_gate: int
    moving_sensitivity: tuple[int, ...]
    still_sensitivity: tuple[int, ...]
    no_one_duration_s: int


def encode_parameters(p: Parameters) -> bytes:
    """ACK data of 0x0061 (for the simulator)."""
    return (bytes((DATA_HEAD, p.max_gate, p.max_moving_gate, p.max_still_gate))
            + bytes(p.moving_sensitivity) + bytes(p.still_sensitivity)
            + struct.pack("<H", p.no_one_duration_s))


def decode_parameters(data: bytes) -> Parameters:
    need(data, 4, "read parameters")
    if data[0] != DATA_HEAD:
        raise ProtocolError(f"read parameters: expected head 0xAA, got 0x{data[0]:02X}")
    n = data[1]
    if n > MAX_GATE:
        raise ProtocolError(f"read parameters: max gate {n} > {MAX_GATE}")
    need(data, 4 + 2 * (n + 1) + 2, "read parameters")
    moving = tuple(data[4:5 + n])
    still = tuple(data[5 + n:6 + 2 * n])
    (duration,) = struct.unpack_from("<H", data, 6 + 2 * n)
    return Parameters(n, data[2], data[3], moving, still, duration)


def firmware_major(version: str) -> int | None:
    """`V2.04.23022511` -> 2 (None for anything that is not such a version)."""
    head = version[1:].split(".", 1)[0] if version.startswith("V") else ""
    return int(head) if head.isdigit() else None


def firmware_has_light_and_out(version: str | None) -> bool:
    """Whether engineering reports of this firmware end with light level and OUT pin.

    Only V2.x defines those two bytes; V1.07 sends two other bytes in their
    place (one real module: "OUT pin" 33), and unknown firmware gets the
    benefit of no doubt: the fields stay empty rather than wrong.
    """
    major = firmware_major(version) if version else None
    return major is not None and major >= 2


def decode_auto_thresholds_status(data: bytes) -> str:
    """0x001B: "not started", "in progress" or "completed"."""
    need(data, 2, "query background noise detection")
    (status,) = struct.unpack_from("<H", data)
    if status not in NOISE_DETECTION_STATUS:
        raise ProtocolError(f"query background noise detection: unknown status {status}")
    return NOISE_DETECTION_STATUS[status]


def decode_resolution(data: bytes) -> float:
    need(data, 2, "read distance resolution")
    (index,) = struct.unpack_from("<H", data)
    if index not in RESOLUTIONS:
        raise ProtocolError(f"read distance resolution: unknown index {index}")
    return RESOLUTIONS[index]


@dataclass(frozen=True, slots=True)
class LightControl:
    """0x00AE: OUT pin light function (0 off, 1 below, 2 above threshold)."""

    function: int
    threshold: int
    out_level: int


def decode_light_control(data: bytes) -> LightControl:
    need(data, 3, "read light control")
    if data[0] > 2 or data[2] > 1:
        raise ProtocolError(f"read light control: bad values {data[:3].hex(' ')}")
    return LightControl(data[0], data[1], data[2])


# --- the incremental parser --------------------------------------------------------


def _check_state(state: int) -> None:
    """Called once the frame's whole structure has been checked."""
    if state > MAX_TARGET_STATE:
        raise UnusualFrame(f"unknown target state {state}")


def _decode_report(payload: bytes) -> Report:
    """A report frame's payload (between length and tail) -> Report, or ProtocolError."""
    length = len(payload)
    if length < BASIC_LENGTH:
        raise ProtocolError("short report")
    kind, head = payload[0], payload[1]
    if head != DATA_HEAD:
        raise ProtocolError("bad 0xAA head")
    if payload[-2:] != DATA_END:
        raise ProtocolError("bad 0x55 0x00 end")
    state, mdist, menergy, sdist, senergy, ddist = struct.unpack_from("<BHBHBH", payload, 2)
    if kind == TYPE_BASIC:
        if length != BASIC_LENGTH:
            raise ProtocolError("bad basic length")
        _check_state(state)
        return Report(state, mdist, menergy, sdist, senergy, ddist)
    if kind != TYPE_ENGINEERING:
        raise ProtocolError("bad data type")
    n_moving, n_still = payload[11], payload[12]
    if n_moving > MAX_GATE or n_still > MAX_GATE:
        raise ProtocolError("bad gate count")
    start_still = 13 + n_moving + 1
    end_still = start_still + n_still + 1
    extra = length - 2 - end_still
    if extra not in (0, 2):
        raise ProtocolError("bad engineering length")
    _check_state(state)
    light = out = None
    if extra == 2:
        light, out = payload[end_still], payload[end_still + 1]
    return Report(
        state, mdist, menergy, sdist, senergy, ddist, engineering=True,
        max_moving_gate=n_moving, max_still_gate=n_still,
        moving_gate_energy=tuple(payload[13:start_still]),
        still_gate_energy=tuple(payload[start_still:end_still]),
        light_level=light, out_pin=out,
    )


def _early_report_check(length: int, kind: int, head: int) -> str:
    """What can be judged from a report's first 8 bytes ("" = plausible so far)."""
    if kind == TYPE_BASIC:
        return "" if length == BASIC_LENGTH and head == DATA_HEAD else "bad basic frame start"
    if kind == TYPE_ENGINEERING:
        # 13 fixed + 2..18 gate energies + 0 or 2 extra + 2 end bytes.
        ok = 17 <= length <= MAX_REPORT_LENGTH and head == DATA_HEAD
        return "" if ok else "bad engineering frame start"
    return "bad data type"


class Parser(FrameParser):
    """LD2410 reports (`F4 F3 F2 F1`, length, payload, `F8 F7 F6 F5`) and command frames.

    Every check of `FrameParser`, plus: the declared length is bounded and a
    false report head is rejected as soon as its first 8 bytes disagree
    (data type, 0xAA head), instead of holding real frames back until its
    claimed length has arrived.
    """

    REPORT_HEAD = REPORT_HEAD

    def _report_end(self, buf: bytearray, start: int, end: int) -> int:
        if end - start < 6:
            raise NeedMore
        (length,) = struct.unpack_from("<H", buf, start + 4)
        if length > MAX_REPORT_LENGTH:
            raise ProtocolError("length too large")
        if end - start >= 8:
            why = _early_report_check(length, buf[start + 6], buf[start + 7])
            if why:
                raise ProtocolError(why)
        frame_end: int = start + 6 + length + 4
        if frame_end > end:
            raise NeedMore
        if buf[frame_end - 4:frame_end] != REPORT_TAIL:
            raise ProtocolError("bad tail")
        return frame_end

    def _decode_report(self, frame: bytes) -> Report:
        return _decode_report(frame[6:-4])

    def feed(self, chunk: bytes | bytearray | memoryview) -> list[Frame]:
        return super().feed(chunk)
