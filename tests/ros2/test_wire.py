"""rmw_zenoh's wire format against the examples of its design doc.

Every literal key below is copied from ros2/rmw_zenoh docs/design.md
(sections "Topic and Service name mapping to Zenoh key expressions" and
"Graph Cache"); the attachment layout from its section "Publishers".
"""

from __future__ import annotations

import struct

import pytest

from buddybot.ros2 import wire
from buddybot.ros2.wire import Attachment, GraphToken, Qos, WireError

HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
SRV_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
STRING = "std_msgs::msg::dds_::String_"
DOC_TOKENS = [
    "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener",
    f"@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/{STRING}/"
    f"{HASH}/::,10:,:,:,,",
    f"@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/{STRING}/"
    f"{HASH}/::,7:,:,:,,",
    "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
    f"example_interfaces::srv::dds_::AddTwoInts_/{SRV_HASH}/::,10:,:,:,,",
    "@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/"
    f"example_interfaces::srv::dds_::AddTwoInts_/{SRV_HASH}/::,10:,:,:,,",
]


def test_topic_keys_equal_the_design_docs() -> None:
    assert wire.topic_key(0, "/chatter", "std_msgs/msg/String", HASH) == \
        f"0/chatter/{STRING}/{HASH}"
    assert wire.topic_key(0, "/robot1/chatter", "std_msgs/msg/String", HASH) == \
        f"0/robot1/chatter/{STRING}/{HASH}"
    assert wire.topic_key(2, "/add_two_ints", "example_interfaces/srv/AddTwoInts", SRV_HASH) \
        == f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{SRV_HASH}"


@pytest.mark.parametrize("ros_type", ["std_msgs/msg/String", "std_srvs/srv/Trigger",
                                      "buddybot_interfaces/msg/LD2410TargetDataFrameArray"])
def test_dds_type_names_round_trip(ros_type: str) -> None:
    assert wire.ros_type_name(wire.dds_type_name(ros_type)) == ros_type


@pytest.mark.parametrize("token", DOC_TOKENS)
def test_graph_tokens_of_the_design_doc_parse_and_format_back(token: str) -> None:
    parsed = GraphToken.parse(token)
    assert parsed.format() == token
    assert parsed.domain_id == 2 and parsed.enclave == "" and parsed.namespace == ""


def test_a_parsed_token_has_its_parts() -> None:
    sub = GraphToken.parse(DOC_TOKENS[1])
    assert (sub.kind, sub.node_name, sub.name, sub.type_name, sub.type_hash) == \
        ("MS", "listener", "/chatter", STRING, HASH)
    assert sub.qos == Qos(depth=10)
    node = GraphToken.parse(DOC_TOKENS[0])
    assert (node.kind, node.node_id, node.entity_id, node.name) == ("NN", 0, 0, None)


def test_a_namespaced_token_mangles_every_slash() -> None:
    token = GraphToken(domain_id=0, session_id="ab12", node_id=3, entity_id=7, kind="MP",
                       enclave="", namespace="/buddy/bot", node_name="bridge",
                       name="/buddy/bot/face_position",
                       type_name="geometry_msgs::msg::dds_::PointStamped_", type_hash=HASH,
                       qos=Qos(reliability=2, durability=1, depth=1))
    text = token.format()
    assert "/%buddy%bot/bridge/%buddy%bot%face_position/" in text
    assert text.endswith("/2:1:,1:,:,:,,")
    assert GraphToken.parse(text) == token


@pytest.mark.parametrize("bad", [
    "@ros2_lv/0/ab/0/0/NN/%/%",  # too short
    "@other/0/ab/0/0/NN/%/%/node",
    "@ros2_lv/x/ab/0/0/NN/%/%/node",
    "@ros2_lv/0/ab/0/0/XX/%/%/node",
    "@ros2_lv/0/ab/0/1/NN/%/%/node",  # a node's entity id is its node id
    "@ros2_lv/0/ZZ/0/0/NN/%/%/node",
    "@ros2_lv/0/ab/0/0/NN/%/%/no de",
    f"@ros2_lv/0/ab/0/1/MP/%/%/n/%t/{STRING}/{HASH}",  # no QoS
    f"@ros2_lv/0/ab/0/1/NN/%/%/n/%t/{STRING}/{HASH}/::,10:,:,:,,",
    f"@ros2_lv/0/ab/0/1/MP/%/%/n/%t/std_msgs/{HASH}/::,10:,:,:,,".replace("std_msgs", "String"),
    f"@ros2_lv/0/ab/0/1/MP/%/%/n/%t/{STRING}/RIHS01_xyz/::,10:,:,:,,",
    f"@ros2_lv/0/ab/0/1/MP/%/%/n/%t/{STRING}/{HASH}/::10:,:,:,,",
    f"@ros2_lv/0/ab/0/1/MP/%/%/n/%t/{STRING}/{HASH}/::,x:,:,:,,",
    f"@ros2_lv/0/ab/0/1/MP/%/%/n/t/{STRING}/{HASH}/::,10:,:,:,,",  # name not absolute
])
def test_malformed_tokens_are_refused(bad: str) -> None:
    with pytest.raises(WireError):
        GraphToken.parse(bad)


@pytest.mark.parametrize(("name", "ok"), [("/a", True), ("/a/b_2", True), ("a", False),
                                          ("/a/", False), ("//a", False), ("/a b", False),
                                          ("/", False)])
def test_names(name: str, ok: bool) -> None:
    if ok:
        assert wire.check_name(name) == name
    else:
        with pytest.raises(WireError):
            wire.check_name(name)


def test_domain_ids_are_bounded() -> None:
    with pytest.raises(WireError, match="domain"):
        wire.topic_key(233, "/a", "std_msgs/msg/String", HASH)


def test_the_attachment_layout_is_the_design_docs() -> None:
    gid = bytes(range(16))
    data = Attachment(sequence=7, timestamp_ns=1_700_000_000_000_000_001, gid=gid).encode()
    assert data == struct.pack("<q", 7) + struct.pack("<q", 1_700_000_000_000_000_001) \
        + b"\x10" + gid
    assert Attachment.decode(data) == Attachment(7, 1_700_000_000_000_000_001, gid)


@pytest.mark.parametrize("data", [b"", bytes(32), bytes(34), bytes(16) + b"\x0f" + bytes(16)])
def test_malformed_attachments_are_refused(data: bytes) -> None:
    with pytest.raises(WireError, match="attachment"):
        Attachment.decode(data)


def test_a_gid_has_16_bytes() -> None:
    with pytest.raises(WireError, match="16"):
        Attachment(1, 2, b"short").encode()


def test_cdr_encapsulation() -> None:
    assert wire.encapsulation(wire.CDR_LE + b"x") == "CDR_LE"
    assert wire.encapsulation(wire.CDR_BE) == "CDR_BE"
    for bad in (b"", b"\x00\x01", b"\x00\x07\x00\x00"):
        with pytest.raises(WireError):
            wire.encapsulation(bad)


def test_entities_key_matches_every_subscription_of_one_topic_and_type() -> None:
    import zenoh

    hash_ = "RIHS01_" + "ab" * 32
    key = wire.entities_key(0, "MS", "/raw_image", "sensor_msgs::msg::dds_::Image_", hash_)
    expr = zenoh.KeyExpr(key)

    def token(name: str, type_hash: str, kind: wire.Kind = "MS", node: str = "viewer",
              namespace: str = "/") -> str:
        return GraphToken(domain_id=0, session_id="8d3f", node_id=2, entity_id=7, kind=kind,
                          enclave="", namespace=namespace, node_name=node, name=name,
                          type_name="sensor_msgs::msg::dds_::Image_", type_hash=type_hash,
                          qos=Qos(reliability=wire.BEST_EFFORT, depth=5)).format()

    assert expr.intersects(zenoh.KeyExpr(token("/raw_image", hash_)))
    assert expr.intersects(zenoh.KeyExpr(token("/raw_image", hash_, namespace="/lab/a")))
    assert not expr.intersects(zenoh.KeyExpr(token("/raw_image", hash_, kind="MP")))
    assert not expr.intersects(zenoh.KeyExpr(token("/debug_image", hash_)))
    assert not expr.intersects(zenoh.KeyExpr(token("/raw_image", "RIHS01_" + "cd" * 32)))
    assert not expr.intersects(zenoh.KeyExpr(token("/robot1/raw_image", hash_)))
    with pytest.raises(WireError):
        wire.entities_key(0, "MS", "raw_image", "sensor_msgs::msg::dds_::Image_", hash_)


def test_a_transient_local_qos_chunk() -> None:
    qos = Qos(durability=wire.TRANSIENT_LOCAL, depth=1)
    assert qos.format() == ":1:,1:,:,:,,"
    assert Qos.parse(":1:,1:,:,:,,") == qos
