"""The shared command envelope: frames, ACKs, the counters both parsers keep."""

from __future__ import annotations

import pytest

from buddybot.radar import envelope as e
from buddybot.radar import ld2410, ld2450


def test_both_models_use_this_one_envelope() -> None:
    assert ld2410.encode_command is e.encode_command and ld2410.Ack is e.Ack
    assert ld2410.COMMAND_NAMES[e.CMD_RESTART] == ld2450.COMMAND_NAMES[e.CMD_RESTART]


def test_ack_and_command_payloads() -> None:
    assert e.decode_command_payload(b"\xa0\x01\x00\x00abc") == e.Ack(0xA0, 0, b"abc")
    assert e.decode_command_payload(b"\xa0\x00xy") == e.Command(0xA0, b"xy")
    for bad in (b"", b"\xa0", b"\xa0\x01\x00"):
        with pytest.raises(e.ProtocolError):
            e.decode_command_payload(bad)


def test_shared_ack_data() -> None:
    assert e.decode_firmware(e.encode_firmware(0, 0x0202, 0x23090617)) == "V2.02.23090617"
    assert e.decode_enable(b"\x01\x00\x40\x00") == e.EnableInfo(1, 64)
    with pytest.raises(e.ProtocolError):
        e.decode_mac(b"\x01\x02")
    with pytest.raises(e.ProtocolError):
        e.set_baud_rate(12345)


def test_error_reasons_stay_bounded() -> None:
    stats = e.ParserStats()
    for i in range(100):
        stats.bad(f"reason {i}")
    stats.bad("reason 0")
    assert stats.bad_frames == 101 and len(stats.errors) == 32 and stats.errors["reason 0"] == 2
