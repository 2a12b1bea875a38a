"""The LD2450 protocol: report decoding, sign-magnitude, commands, the parser (pure, no I/O)."""

from __future__ import annotations

import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from buddybot.radar import envelope
from buddybot.radar import ld2450 as p
from tests.properties import examples
from tests.radar.rig import check_any_chunking, feed_in_cuts, mutate

# The protocol document's example: one target at x -782 mm, y 1713 mm, -16 cm/s, 320 mm.
DOC_REPORT = bytes.fromhex("AAFF0300 0E03 B186 1000 4001" + "00" * 16 + "55CC")


def target(x: int = -782, y: int = 1713, speed: int = -16, res: int = 320) -> p.Target:
    return p.Target(x, y, speed, res)


def report(*slots: p.Target | None) -> p.Report:
    full = [*slots, None, None, None][:3]
    return p.Report(tuple(full))


def parse_all(data: bytes, parser: p.Parser | None = None) -> list[p.Frame]:
    return (parser or p.Parser()).feed(data)


# --- the documented example and the field layout ------------------------------------------


def test_document_example_is_sign_magnitude_not_twos_complement() -> None:
    [frame] = parse_all(DOC_REPORT)
    assert frame == report(target())
    assert isinstance(frame, p.Report)
    [(slot, t)] = frame.targets()
    assert slot == 0 and (t.x_mm, t.y_mm, t.speed_cms, t.resolution_mm) == (-782, 1713, -16, 320)
    # Read as two's complement the same words would put the person at x +782, y -31055.
    assert struct.unpack_from("<hh", DOC_REPORT, 4) == (782, -31055)


def test_encode_report_reproduces_the_document_bytes() -> None:
    assert p.encode_report(report(target())) == DOC_REPORT
    assert len(DOC_REPORT) == p.REPORT_SIZE == 30


@pytest.mark.parametrize(("word", "value"), [
    (0x0000, 0), (0x8000, 0), (0x8001, 1), (0x0001, -1), (0x830E, 782), (0x030E, -782),
    (0xFFFF, 32767), (0x7FFF, -32767), (0x8FA0, 4000), (0x0FA0, -4000), (0x9F40, 8000),
])
def test_sign_magnitude_words(word: int, value: int) -> None:
    assert p.decode_sign_magnitude(word) == value
    if word != 0x8000:  # zero is sent as 0x0000
        assert p.encode_sign_magnitude(value) == word


def test_sign_magnitude_refuses_what_does_not_fit() -> None:
    with pytest.raises(p.ProtocolError):
        p.encode_sign_magnitude(32768)
    with pytest.raises(p.ProtocolError):
        p.encode_sign_magnitude(-40000)


def test_slots_keep_their_index_and_empty_slots_are_none() -> None:
    frame = report(None, target(1200, 3000, 25, 360), target(-4000, 8000, 0, 320))
    [parsed] = parse_all(p.encode_report(frame))
    assert parsed == frame
    assert isinstance(parsed, p.Report)
    assert [s for s, _ in parsed.targets()] == [1, 2]
    assert parsed.slots[0] is None


@pytest.mark.parametrize(("x", "y", "plausible"), [
    (4000, 0, True), (-4000, 8000, True), (0, 8000, True), (4001, 100, False),
    (-4001, 100, False), (100, 8001, False), (100, -1, False),
])
def test_targets_at_the_limits_of_the_field(x: int, y: int, plausible: bool) -> None:
    t = target(x, y, 0, 320)
    [parsed] = parse_all(p.encode_report(report(t)))
    assert isinstance(parsed, p.Report) and parsed.slots[0] == t
    assert t.plausible() is plausible


def test_a_target_on_the_sensor_itself_is_no_target() -> None:
    """x = y = 0 (whatever the sign bits, speed, resolution) is an empty slot."""
    data = bytearray(p.encode_report(report()))
    struct.pack_into("<HHHH", data, 4, 0x8000, 0x8000, 0x0005, 320)
    [parsed] = parse_all(bytes(data))
    assert parsed == report()


def test_encode_report_refuses_bad_reports() -> None:
    with pytest.raises(p.ProtocolError):
        p.encode_report(p.Report((None, None)))
    with pytest.raises(p.ProtocolError):
        p.encode_report(report(target(res=70000)))
    with pytest.raises(p.ProtocolError):
        p.decode_report(DOC_REPORT[:-1])
    with pytest.raises(p.ProtocolError):
        p.decode_report(b"\x00" + DOC_REPORT[1:])
    with pytest.raises(p.ProtocolError):
        p.decode_report(DOC_REPORT[:-1] + b"\x00")


# --- commands and ACKs --------------------------------------------------------------------


def test_command_frames() -> None:
    assert p.single_target() == bytes.fromhex("FDFCFBFA02008000 04030201".replace(" ", ""))
    assert p.multi_target() == bytes.fromhex("FDFCFBFA02009000 04030201".replace(" ", ""))
    assert p.query_tracking_mode() == bytes.fromhex("FDFCFBFA0200910004030201")
    assert p.query_zone_filter() == bytes.fromhex("FDFCFBFA0200C10004030201")
    zf = p.ZoneFilter(p.ZONE_DETECT_ONLY, (p.Zone(-1000, 0, 1000, 2000), p.EMPTY_ZONE,
                                            p.EMPTY_ZONE))
    assert p.set_zone_filter(zf) == bytes.fromhex(
        "FDFCFBFA 1C00 C200 0100 18FC 0000 E803 D007" + "00" * 16 + "04030201")
    # The shared envelope: the same bytes as the LD2410's.
    assert envelope.enable_config() == bytes.fromhex("FDFCFBFA0400FF00010004030201")
    assert envelope.end_config() == bytes.fromhex("FDFCFBFA0200FE0004030201")
    assert envelope.read_firmware() == bytes.fromhex("FDFCFBFA0200A00004030201")
    assert envelope.set_baud_rate(115200) == bytes.fromhex("FDFCFBFA0400A100050004030201")
    assert envelope.factory_reset() == bytes.fromhex("FDFCFBFA0200A20004030201")
    assert envelope.restart() == bytes.fromhex("FDFCFBFA0200A30004030201")
    assert envelope.bluetooth(True) == bytes.fromhex("FDFCFBFA0400A400010004030201")
    assert envelope.read_mac() == bytes.fromhex("FDFCFBFA0400A500010004030201")


def test_acks_decode() -> None:
    single = bytes.fromhex("FDFCFBFA 0600 9101 0000 0100 04030201".replace(" ", ""))
    multi = envelope.encode_ack(p.CMD_QUERY_TRACKING_MODE, 0, b"\x02\x00")
    zf = p.ZoneFilter(p.ZONE_IGNORE, (p.Zone(-500, 100, 500, 900), p.Zone(1, 2, 3, 4),
                                      p.Zone(-4000, 0, 4000, 8000)))
    zones = envelope.encode_ack(p.CMD_QUERY_ZONE_FILTER, 0, p.encode_zone_filter(zf))
    mac = envelope.encode_ack(envelope.CMD_READ_MAC, 0, bytes.fromhex("080504030201"))
    frames = parse_all(single + multi + zones + mac)
    assert [f.command for f in frames if isinstance(f, p.Ack)] == [0x91, 0x91, 0xC1, 0xA5]
    a, b, c, d = (f for f in frames if isinstance(f, p.Ack))
    assert p.decode_tracking_mode(a.data) == "single"
    assert p.decode_tracking_mode(b.data) == "multi"
    assert p.decode_zone_filter(c.data) == zf and zf.mode_name == "ignore-inside"
    assert envelope.decode_mac(d.data) == p.BLUETOOTH_OFF_MAC


def test_encoders_and_decoders_refuse_nonsense() -> None:
    with pytest.raises(p.ProtocolError):
        p.set_zone_filter(p.ZoneFilter(3))
    with pytest.raises(p.ProtocolError):
        p.set_zone_filter(p.ZoneFilter(1, (p.EMPTY_ZONE,)))
    with pytest.raises(p.ProtocolError):
        p.set_zone_filter(p.ZoneFilter(1, (p.Zone(0, 0, 40000, 1),) + (p.EMPTY_ZONE,) * 2))
    with pytest.raises(p.ProtocolError):
        p.decode_tracking_mode(b"\x03\x00")
    with pytest.raises(p.ProtocolError):
        p.decode_tracking_mode(b"\x01")
    with pytest.raises(p.ProtocolError):
        p.decode_zone_filter(b"\x01\x00" + bytes(10))
    with pytest.raises(p.ProtocolError):
        p.decode_zone_filter(b"\x07\x00" + bytes(24))


# --- robustness ---------------------------------------------------------------------------

STREAM_FRAMES = [report(target()), report(), report(None, target(3999, 7999, 120, 360)),
                 report(target(-1, 1, 1, 1), target(2, 2, -2, 2), target(-3, 3, 3, 3))]
STREAM = b"".join(p.encode_report(f) for f in STREAM_FRAMES)


def test_split_at_every_byte_boundary_and_byte_by_byte() -> None:
    check_any_chunking(p.Parser, STREAM, STREAM_FRAMES)


def test_garbage_stray_heads_and_truncated_frames_cost_only_themselves() -> None:
    garbage = [b"\x00\x01hello\n", b"\xaa", b"\xaa\xff\x03\x00", DOC_REPORT[:17],
               b"\xfd\xfc", b"\x55\xcc\x55\xcc", b"\xf4\xf3\xf2\xf1\x0d\x00"]
    data = b"".join(g + p.encode_report(f) for g, f in zip(garbage, STREAM_FRAMES * 2,
                                                             strict=False))
    parser = p.Parser()
    assert parser.feed(data) == (STREAM_FRAMES * 2)[:len(garbage)]
    assert parser.stats.skipped_bytes > 0 and parser.stats.bad_frames >= 1


def test_ld2410_frames_are_not_ld2450_frames() -> None:
    from buddybot.radar import ld2410

    data = ld2410.encode_report(ld2410.Report(1, 100, 50, 100, 50, 100)) * 5
    parser = p.Parser()
    assert parser.feed(data) == []
    assert parser.stats.reports == 0


def test_buffer_stays_bounded_on_endless_garbage() -> None:
    parser = p.Parser()
    for _ in range(1000):
        assert parser.feed(b"\x00\xaa\x11" * 50) == []
    assert len(parser._buf) <= 3


@pytest.mark.timeout(60)  # a hang guard: ~1 s now, minutes when quadratic
def test_many_megabytes_in_one_feed_take_linear_time_and_lose_nothing() -> None:
    rng = random.Random(5)
    frames = [report(target(rng.randrange(-4000, 4001), rng.randrange(1, 8001),
                            rng.randrange(-300, 301), 320)) for _ in range(100)]
    garbage = bytes(b for b in rng.randbytes(40) if b not in (0xAA, 0xFD)) + b"\xaa\xff\x03"
    blob = bytearray()
    expected: list[p.Frame] = []
    while len(blob) < 4_000_000:
        for frame in frames:
            blob += garbage[:rng.randrange(len(garbage))] + p.encode_report(frame)
            expected.append(frame)
    ack = envelope.encode_ack(p.CMD_QUERY_TRACKING_MODE, 0, b"\x02\x00")
    blob += ack
    expected.append(p.Ack(p.CMD_QUERY_TRACKING_MODE, 0, b"\x02\x00"))
    parser = p.Parser()
    assert parser.feed(bytes(blob)) == expected
    assert len(parser._buf) <= 3


# --- property-based -----------------------------------------------------------------------

magnitudes = st.integers(-p.MAGNITUDE_MAX, p.MAGNITUDE_MAX)


@st.composite
def targets(draw: st.DrawFn) -> p.Target | None:
    if draw(st.booleans()):
        return None
    y = draw(st.integers(1, p.MAGNITUDE_MAX))
    return p.Target(draw(magnitudes), y, draw(magnitudes), draw(st.integers(0, 0xFFFF)))


reports = st.lists(targets(), min_size=3, max_size=3).map(lambda s: p.Report(tuple(s)))

# Noise may not contain report-end bytes or a command head: noise that completes a
# truncated frame with its own missing end *is* that frame on the wire (no checksum).
_NOISE_BYTE = st.integers(0, 255).filter(lambda b: b not in (0x55, 0xCC, 0xFD))


def noise(min_size: int = 0, max_size: int = 12) -> st.SearchStrategy[bytes]:
    return st.lists(_NOISE_BYTE, min_size=min_size, max_size=max_size).map(bytes)


@st.composite
def mutated_streams(draw: st.DrawFn) -> tuple[bytes, list[p.Report], list[p.Report], list[int]]:
    frames = draw(st.lists(reports, min_size=1, max_size=8))
    out = bytearray()
    intact: list[p.Report] = []
    for frame in frames:
        out += draw(noise())
        # Structural bytes: the head and the 55 CC end.
        data, kind = mutate(draw, p.encode_report(frame), noise(1, 5), [0, 1, 2, 3, 28, 29])
        if kind == "intact":
            intact.append(frame)
        out += data
    cuts = draw(st.lists(st.integers(0, len(out)), max_size=6))
    return bytes(out), frames, intact, sorted(cuts)


@settings(max_examples=examples(400))
@given(mutated_streams())
def test_mutated_streams_yield_every_intact_frame_and_nothing_unsent(
        case: tuple[bytes, list[p.Report], list[p.Report], list[int]]) -> None:
    data, sent, intact, cuts = case
    parser = p.Parser()
    got: list[p.Frame] = feed_in_cuts(parser, data, cuts)
    got += parser.feed(bytes(p.REPORT_SIZE + 10))  # a live stream keeps sending
    # Nothing that was not sent.
    assert all(frame in sent for frame in got)
    remaining = iter(got)
    assert all(any(frame == g for g in remaining) for frame in intact)


@settings(max_examples=examples(300))
@given(st.binary(max_size=3000), st.lists(st.integers(1, 64), max_size=20))
def test_random_bytes_never_raise_and_stay_bounded(data: bytes, chunks: list[int]) -> None:
    parser = p.Parser()
    pos = 0
    for size in [*chunks, len(data)]:
        for frame in parser.feed(data[pos:pos + size]):
            assert isinstance(frame, p.Report | p.Ack | p.Command)
        pos += size
    assert len(parser._buf) <= 6 + envelope.MAX_COMMAND_LENGTH + 4


@settings(max_examples=examples(200))
@given(st.lists(reports, min_size=1, max_size=5))
def test_encode_then_parse_round_trips(frames: list[p.Report]) -> None:
    assert parse_all(b"".join(p.encode_report(f) for f in frames)) == frames
