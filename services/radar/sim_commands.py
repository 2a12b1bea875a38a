"""How every simulated sensor answers a command frame (pure): the envelope's rules.

Both models (sim.SimulatedLD2410, ld2450_sim.SimulatedLD2450) answer alike:
enable configuration is always accepted (ACK data: protocol version 1,
buffer size 0x40), any other command outside configuration mode gets a
failure ACK, and a command the model's `_apply` refuses (ValueError) too. A
sensor built with `answer_commands=False` never answers (error paths).
"""

from __future__ import annotations

import struct

from buddybot.radar import envelope as e


class AnswersCommands:
    """Mixin: `handle()` for a simulator with `commands`, `answer_commands`,
    `config_mode`, `firmware`, `baud_index`, `bluetooth` and its model's
    `_apply(word, value, now) -> ACK data`. The words both models share and
    answer alike (end configuration, firmware, baud rate, Bluetooth) are
    answered here."""

    commands: list[int]
    answer_commands: bool
    config_mode: bool
    firmware: tuple[int, int, int]
    baud_index: int
    bluetooth: bool

    def _apply_shared(self, word: int, value: bytes) -> bytes | None:
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
        else:
            return None
        return b""

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
            data = self._apply_shared(word, value)
            if data is None:
                data = self._apply(word, value, now)
        except (ValueError, struct.error):
            return e.encode_ack(word, 1)
        return e.encode_ack(word, 0, data)
