"""How every simulated sensor answers a command frame (pure): the envelope's rules.

Both models (sim.SimulatedLD2410, ld2450_sim.SimulatedLD2450) answer alike:
enable configuration is always accepted (ACK data: protocol version 1,
buffer size 0x40), any other command outside configuration mode gets a
failure ACK, and a command the model's `_apply` refuses (ValueError) too. A
sensor built with `answer_commands=False` never answers (error paths).
"""

from __future__ import annotations

import random
import struct
from dataclasses import KW_ONLY, dataclass, field

from buddybot.radar import envelope as e

FACTORY_BAUD_INDEX = 7
"""256000 baud, both models' factory setting."""
RESTART_SILENT_S = 0.5
"""How long a sensor sends nothing after a restart."""


@dataclass
class AnswersCommands:
    """The state and `handle()` both simulators share: the command log, the
    configuration mode, the shared settings (baud rate, Bluetooth, firmware:
    each model gives its own default), the restart/factory-reset counters,
    the reports' random source, and its model's `_apply(word, value, now) ->
    ACK data`. The words both models share and answer alike (end
    configuration, firmware, baud rate, Bluetooth, restart, factory reset)
    are answered here; a model adds to a restart or a factory reset in
    `_restarted()` and `_factory_defaults()`. Every field is keyword-only."""

    _: KW_ONLY
    firmware: tuple[int, int, int]
    seed: int = 1
    answer_commands: bool = True  # False: a sensor that never ACKs (for error paths)
    baud_index: int = FACTORY_BAUD_INDEX
    bluetooth: bool = True
    config_mode: bool = False
    restarts: int = 0
    factory_resets: int = 0
    commands: list[int] = field(default_factory=list)
    _silent_until: float = 0.0

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)

    def silent(self, now: float) -> bool:
        """Whether the sensor sends no reports now: configuring, or rebooting."""
        return self.config_mode or now < self._silent_until

    def _apply_shared(self, word: int, value: bytes, now: float) -> bytes | None:
        """ACK data of a shared word (None: not one of them)."""
        if word == e.CMD_END_CONFIG:
            self.config_mode = False
        elif word == e.CMD_READ_FIRMWARE:
            return e.encode_firmware(*self.firmware)
        elif word == e.CMD_SET_BAUD_RATE:
            (index,) = struct.unpack("<H", value)
            if index not in e.BAUD_RATES.values():
                raise ValueError("bad baud index")
            self.baud_index = index
        elif word == e.CMD_BLUETOOTH:
            (flag,) = struct.unpack("<H", value)
            self.bluetooth = bool(flag)
        elif word == e.CMD_FACTORY_RESET:
            self.factory_resets += 1
            self.baud_index = FACTORY_BAUD_INDEX
            self._factory_defaults()
        elif word == e.CMD_RESTART:
            # ACKed, then the module reboots: silent for a moment, config mode left.
            self.restarts += 1
            self.config_mode = False
            self._silent_until = now + RESTART_SILENT_S
            self._restarted()
        else:
            return None
        return b""

    def _factory_defaults(self) -> None:
        """The model's own settings back to the factory's."""

    def _restarted(self) -> None:
        """What else the model forgets across a restart."""

    def _apply(self, word: int, value: bytes, now: float) -> bytes:
        raise NotImplementedError

    def handle(self, command: e.Command, now: float) -> bytes:
        """The ACK for one command frame (b"" if this sensor does not answer)."""
        self.commands.append(command.command)
        if not self.answer_commands:
            return b""
        word, value = command.command, command.value
        if word == e.CMD_ENABLE_CONFIG:
            self.config_mode = True
            return e.encode_ack(word, 0, struct.pack("<HH", 1, 0x40))
        if not self.config_mode:
            return e.encode_ack(word, 1)
        try:
            data = self._apply_shared(word, value, now)
            if data is None:
                data = self._apply(word, value, now)
        except (ValueError, struct.error):
            return e.encode_ack(word, 1)
        return e.encode_ack(word, 0, data)
