"""Configuration commands over an open port: send, wait for the matching ACK, check status.

The LD2410 and the LD2450 share the command envelope (envelope.py), so one
client talks to both: the shared words (firmware, baud rate, restart,
factory reset, Bluetooth, MAC) work on either, the others on their model.

Works with any object that has `read(n)`, `write(data)` and `in_waiting`
(a pyserial port, whatever its URL), so it imports nothing from serial.
Every operation is wrapped in enable configuration ... end configuration,
as the protocol requires; report frames that keep arriving meanwhile are
skipped by the parser.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

from buddybot.radar import ld2410 as p
from buddybot.radar import ld2450


class Port(Protocol):
    in_waiting: int

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...


class RadarError(Exception):
    """The sensor did not ACK a command, or ACKed it with a failure status."""


class LD2410Client:
    """Talks to one sensor: `with client.configuring(): client.read_firmware()`."""

    def __init__(self, port: Port, timeout_s: float = 1.0, attempts: int = 2,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.port = port
        self.timeout_s = timeout_s
        self.attempts = attempts
        self._clock = clock
        self._parser = p.Parser()
        self.enable_info: p.EnableInfo | None = None
        self._configuring = False

    def command(self, frame: bytes, word: int) -> p.Ack:
        """Send `frame` and return the ACK for `word`; RadarError if none or failed."""
        name = p.COMMAND_NAMES.get(word) or ld2450.COMMAND_NAMES.get(word, f"0x{word:04X}")
        for _ in range(self.attempts):
            self.port.write(frame)
            ack = self._wait_ack(word)
            if ack is None:
                continue
            if not ack.ok:
                raise RadarError(f"sensor refused '{name}' (status {ack.status})")
            return ack
        raise RadarError(
            f"no ACK for '{name}' within {self.timeout_s:g} s x{self.attempts} "
            "(wrong port or baud rate, sensor busy, or another program reading the port?)"
        )

    def _wait_ack(self, word: int) -> p.Ack | None:
        end = self._clock() + self.timeout_s
        while self._clock() < end:
            data = self.port.read(self.port.in_waiting or 1)
            for frame in self._parser.feed(data):
                if isinstance(frame, p.Ack) and frame.command == word:
                    return frame
        return None

    @contextmanager
    def configuring(self) -> Iterator[p.EnableInfo]:
        """Enable configuration; end it afterwards even when a command failed."""
        ack = self.command(p.enable_config(), p.CMD_ENABLE_CONFIG)
        self.enable_info = p.decode_enable(ack.data)
        self._configuring = True
        try:
            yield self.enable_info
        finally:
            if self._configuring:  # a restart already left configuration mode
                self._configuring = False
                self.command(p.end_config(), p.CMD_END_CONFIG)

    # -- the operations (call inside `configuring()`) --

    def read_firmware(self) -> str:
        return p.decode_firmware(self.command(p.read_firmware(), p.CMD_READ_FIRMWARE).data)

    def read_parameters(self) -> p.Parameters:
        return p.decode_parameters(self.command(p.read_parameters(), p.CMD_READ_PARAMETERS).data)

    def read_resolution(self) -> float:
        ack = self.command(p.read_resolution(), p.CMD_READ_RESOLUTION)
        return p.decode_resolution(ack.data)

    def read_mac(self) -> str:
        return p.decode_mac(self.command(p.read_mac(), p.CMD_READ_MAC).data)

    def set_engineering(self, on: bool) -> None:
        word = p.CMD_ENGINEERING_ON if on else p.CMD_ENGINEERING_OFF
        self.command(p.engineering_mode(on), word)

    def set_max_gates(self, moving: int, still: int, no_one_duration_s: int) -> None:
        self.command(p.set_max_gates(moving, still, no_one_duration_s), p.CMD_SET_MAX_GATES)

    def set_sensitivity(self, gate: int | None, moving: int, still: int) -> None:
        self.command(p.set_gate_sensitivity(gate, moving, still), p.CMD_SET_SENSITIVITY)

    def set_resolution(self, metres_per_gate: float) -> None:
        self.command(p.set_resolution(metres_per_gate), p.CMD_SET_RESOLUTION)

    def restart(self) -> None:
        """Restart the module; it reboots out of configuration mode, so no end command."""
        self.command(p.restart(), p.CMD_RESTART)
        self._configuring = False

    def factory_reset(self) -> None:
        self.command(p.factory_reset(), p.CMD_FACTORY_RESET)

    def set_baud_rate(self, baud: int) -> None:
        """Takes effect after a restart: the reader must then open the port at `baud`."""
        self.command(p.set_baud_rate(baud), p.CMD_SET_BAUD_RATE)

    def set_bluetooth(self, on: bool) -> None:
        """Takes effect after a restart."""
        self.command(p.bluetooth(on), p.CMD_BLUETOOTH)

    def start_auto_thresholds(self, duration_s: int) -> None:
        """LD2410C: measure background noise for `duration_s` and set thresholds from it."""
        self.command(p.start_auto_thresholds(duration_s), p.CMD_AUTO_THRESHOLDS)

    def auto_thresholds_status(self) -> str:
        ack = self.command(p.query_auto_thresholds(), p.CMD_AUTO_THRESHOLDS_STATUS)
        return p.decode_auto_thresholds_status(ack.data)

    def bluetooth_auth(self, password: str) -> None:
        """LD2410C 0x00A8: obtain Bluetooth permissions (refused on a wrong password)."""
        self.command(p.bluetooth_auth(password), p.CMD_BLUETOOTH_AUTH)

    def set_bluetooth_password(self, password: str) -> None:
        self.command(p.set_bluetooth_password(password), p.CMD_BLUETOOTH_PASSWORD)

    # -- LD2450 --

    def set_tracking_mode(self, multi: bool) -> None:
        """LD2450: track up to three targets (multi) or one (single)."""
        if multi:
            self.command(ld2450.multi_target(), ld2450.CMD_MULTI_TARGET)
        else:
            self.command(ld2450.single_target(), ld2450.CMD_SINGLE_TARGET)

    def read_tracking_mode(self) -> str:
        ack = self.command(ld2450.query_tracking_mode(), ld2450.CMD_QUERY_TRACKING_MODE)
        return ld2450.decode_tracking_mode(ack.data)

    def read_zone_filter(self) -> ld2450.ZoneFilter:
        ack = self.command(ld2450.query_zone_filter(), ld2450.CMD_QUERY_ZONE_FILTER)
        return ld2450.decode_zone_filter(ack.data)

    def set_zone_filter(self, zf: ld2450.ZoneFilter) -> None:
        self.command(ld2450.set_zone_filter(zf), ld2450.CMD_SET_ZONE_FILTER)
