"""ROS 2 service requests and responses, checked against mcap-ros2-support's CDR
(not ours), reading the checked-in `.srv` file, and bad input refused."""

from __future__ import annotations

import struct

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import convert, interfaces, services, types, wire

from .test_convert import their_decoder, their_encoder

SRV = (interfaces.ROOT / "srv" / "PlayAudioFile.srv").read_text()
REQUEST, RESPONSE = (part.lstrip("\n") for part in SRV.split("\n---\n"))
TRIGGER_RESPONSE = "bool success\nstring message\n"
BY_NAME = {entry.name: entry for entry in services.SERVICES}
PLAY, STOP = BY_NAME["play_audio_file"], BY_NAME["stop_audio_file"]


def test_the_table_is_the_seeds_services_on_our_keys() -> None:
    assert {(e.name, e.ros_type, e.service.pattern) for e in services.SERVICES} == {
        ("play_audio_file", services.PLAY_AUDIO_FILE, keys.PLAY_FILE.pattern),
        ("stop_audio_file", types.TRIGGER, keys.AUDIO_STOP.pattern),
        ("pause_audio_file", types.TRIGGER, keys.AUDIO_PAUSE.pattern),
        ("resume_audio_file", types.TRIGGER, keys.AUDIO_RESUME.pattern),
    }
    for entry in services.SERVICES:
        assert entry.service.reply is m.TriggerReply
        assert types.type_hash(entry.ros_type).startswith("RIHS01_")


def test_a_play_request_encoded_by_another_implementation() -> None:
    payload = their_encoder("buddybot_interfaces/msg/PlayAudioFile_Request", REQUEST)(
        {"path": "chime.wav"})
    assert services.request_from_ros(payload, PLAY) == m.PlayAudioFile(path="chime.wav")


def test_a_trigger_request_is_rosidls_one_byte_struct() -> None:
    assert services.request_from_ros(wire.CDR_LE + b"\x00", STOP) == m.Trigger()


@pytest.mark.parametrize("entry", [PLAY, STOP])
def test_a_response_decodes_with_another_implementation(entry: services.RosService) -> None:
    schema = RESPONSE if entry is PLAY else TRIGGER_RESPONSE
    name = f"x/{entry.ros_type.rsplit('/', 1)[1]}_Response"
    decoded = their_decoder(name, schema)(
        services.reply_to_ros(m.TriggerReply(success=False, message="no player"), entry))
    assert (decoded.success, decoded.message) == (False, "no player")


@pytest.mark.parametrize("payload", [
    b"", b"\x00\x01", b"garbage!", wire.CDR_LE,
    wire.CDR_LE + struct.pack("<I", 1 << 30) + b"abc",  # a string longer than the payload
    wire.CDR_LE + struct.pack("<I", 1) + b"\x00",  # an empty path: min length 1
    wire.CDR_LE + struct.pack("<I", 5000) + b"a" * 4999 + b"\x00",  # over string<=4096
    b"\x00\x01\x00\x00" + b"\x00" * (convert.MAX_PAYLOAD + 1),
])
def test_bad_play_requests_are_refused(payload: bytes) -> None:
    with pytest.raises(convert.ConvertError):
        services.request_from_ros(payload, PLAY)


def test_bytes_left_over_in_a_trigger_are_refused() -> None:
    with pytest.raises(convert.ConvertError):
        services.request_from_ros(wire.CDR_LE + b"\x00" * 12, STOP)


def test_the_reply_carries_the_requests_sequence_and_gid_back() -> None:
    gid = bytes(range(16))
    info = services.request_info(wire.Attachment(41, 5, gid).encode())
    back = wire.Attachment.decode(services.reply_attachment(info, 99))
    assert (back.sequence, back.timestamp_ns, back.gid) == (41, 99, gid)


@pytest.mark.parametrize("attachment", [
    None, b"", b"\x00" * 10, wire.Attachment(-1, 5, bytes(16)).encode(),
    struct.pack("<qqB", 1, 5, 8) + bytes(16),
])
def test_a_request_without_a_good_attachment_is_refused(attachment: bytes | None) -> None:
    with pytest.raises(wire.WireError):
        services.request_info(attachment)
