"""Recognising the sensor model from its frames (pure)."""

from __future__ import annotations

import pytest

from buddybot.radar import envelope, ld2410, ld2450
from buddybot.radar.models import LD2410, LD2450, Sniffer, describe

BASIC = ld2410.encode_report(ld2410.Report(1, 100, 50, 100, 50, 100))
ENGINEERING = ld2410.encode_report(ld2410.Report(
    1, 100, 50, 100, 50, 100, engineering=True, max_moving_gate=8, max_still_gate=8,
    moving_gate_energy=tuple(range(9)), still_gate_energy=tuple(range(9))))
ANGLE = ld2450.encode_report(ld2450.Report((ld2450.Target(-500, 1500, 0, 320), None, None)))


@pytest.mark.parametrize(("data", "model", "kind"), [
    (BASIC, LD2410, "LD2410 basic"), (ENGINEERING, LD2410, "LD2410 engineering"),
    (ANGLE, LD2450, "LD2450"),
])
def test_recognised_from_the_first_report_and_nothing_read_is_lost(
        data: bytes, model: str, kind: str) -> None:
    sniffer = Sniffer()
    ack = envelope.encode_ack(envelope.CMD_READ_FIRMWARE, 0, bytes(8))
    got = sniffer.feed(b"\x00garbage" + ack + data[:7])
    assert got == [] and sniffer.model is None
    got = sniffer.feed(data[7:] + data)
    assert sniffer.model == model
    assert [describe(f) for f in got] == [None, kind, kind]  # the ACK, both reports
    assert sniffer.intact_frames == 3


def test_an_explicit_model_never_guesses() -> None:
    sniffer = Sniffer(LD2450)
    assert sniffer.feed(BASIC * 3) == [] and sniffer.model == LD2450
    assert sniffer.skipped_bytes > 0
    with pytest.raises(ValueError):
        Sniffer("LD9999")


def test_garbage_is_counted_while_recognising() -> None:
    sniffer = Sniffer()
    assert sniffer.feed(bytes(range(256)) * 4 + BASIC[:-1] + b"\x00") == []
    assert sniffer.skipped_bytes > 0 and sniffer.bad_frames == 1
