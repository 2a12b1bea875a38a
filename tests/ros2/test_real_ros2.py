"""Real ROS 2 Jazzy (the `ros-jazzy-*` wheels: rosidl and rclpy) against our
types, CDR and bags.

Our own tests check the bridge against readers that are not ours but are not
ROS either (rosbags, mcap-ros2-support); here ROS 2's own code answers, in
the venv scripts/ros2-venv.sh makes (BUDDYBOT_ROS2_PYTHON names its Python),
run as a subprocess (`rclpy_side.py`) with JSON files between the two:

* every type of our typestore has the hash real rosidl gives it: from the
  wheels' type descriptions (real definitions), from our checked-in
  `buddybot_interfaces` put through rosidl as a build would, or, for the
  packages no wheel ships (tf2_msgs, statistics_msgs, hri_msgs, ...), from
  our typestore's definition put through rosidl: then the hashing is real
  ROS's, the definition ours. Every type the bridge and the bag use is of
  the first two kinds, or this test says so;
* every message the bridge publishes (each topic, the services' responses,
  the action's status, feedback and replies), on sample values: where the
  wheels have the type's Python typesupport (std_msgs, geometry_msgs,
  sensor_msgs, std_srvs, action_msgs), rclpy decodes our CDR to the values
  meant (spelled here from the types' definitions), and its own encoding of
  them decodes with ours to the same and equals our bytes but for CDR
  padding, which Fast-CDR leaves unwritten; our own types and packages
  without a wheel have no typesupport here (Jazzy's rclpy cannot make one
  at run time), so for them only the hash is real ROS's;
* an exported bag: each channel's `topic_type_hash` and metadata.yaml's
  `type_description_hash` are real ROS's, and every message of a standard
  type passes the same check against the recorded values.

Skipped, saying why, where the venv cannot be made (offline).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader

from buddybot import cli
from buddybot.contract import channels
from buddybot.contract import messages as m
from buddybot.ros2 import action, bridge, convert, hri, rosbag, services, types
from buddybot.runtime.config import default_config
from tests.cache import cache_root
from tests.contract.test_messages import sample_messages
from tests.tools.test_bag import samples, write_recording

pytestmark = [pytest.mark.integration,
              pytest.mark.xdist_group("real_ros2")]  # one worker computes the hashes once

ROOT = Path(__file__).resolve().parents[2]
SIDE = Path(__file__).with_name("rclpy_side.py")
PACKAGE = ROOT / "ros2" / types.OURS


def ros_python() -> str:
    """BUDDYBOT_ROS2_PYTHON, else the venv scripts/ros2-venv.sh already made; skip
    without (installing it is scripts/test.sh's work, not a test's)."""
    if os.environ.get("BUDDYBOT_ROS2_PYTHON"):
        return os.environ["BUDDYBOT_ROS2_PYTHON"]
    made = sorted(cache_root().glob("ros2-jazzy-*/.complete"), key=lambda p: p.stat().st_mtime)
    if made:  # the newest: the script names a venv by its pins
        return str(made[-1].parent / "bin" / "python")
    pytest.skip("ROS 2 Jazzy's wheels are not installed (not a test dependency): "
                "scripts/ros2-venv.sh installs them in a venv of its own")


def side(python: str, *argv: str) -> None:
    done = subprocess.run([python, str(SIDE), *argv], capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-4000:]


# --- hashes ------------------------------------------------------------------------


NO_WHEEL_SAMPLE = "tf2_msgs/msg/TFMessage"
"""A type of a package no wheel ships: hashed by rosidl from our store's
definition, a path any such type the bridge adds (hri_msgs, ...) takes."""


def write_extra(folder: Path) -> None:
    """`.msg` files, from our store, of its `msg` types outside our package (used
    by rosidl only for packages no wheel ships)."""
    store = types.typestore()
    for name in sorted(store.fielddefs):
        package, kind, base = name.split("/")
        if kind != "msg" or package == types.OURS:
            continue
        text, _md5 = store.gendefhash(name, {}, 2)
        path = folder / package / "msg" / f"{base}.msg"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


@pytest.fixture(scope="module")
def python() -> str:
    return ros_python()


@pytest.fixture(scope="module")
def real_hashes(python: str, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """What real rosidl says: {"hashes": {type: [hash, source]}, "packages": [...]}."""
    folder = tmp_path_factory.mktemp("hashes")
    write_extra(folder / "extra")
    side(python, "hashes", str(PACKAGE), str(folder / "extra"), str(folder / "out.json"))
    result: dict[str, Any] = json.loads((folder / "out.json").read_text())
    assert not result["errors"], result["errors"]
    return result


def hash_problems(real: dict[str, list[str]], ours: dict[str, str]) -> list[str]:
    """What differs: a type whose hash is not real rosidl's, or one real rosidl
    gave no hash for."""
    return [f"{name}: ours {value}, " + (f"{real[name][1]}: {real[name][0]}"
                                          if name in real else "no hash from real rosidl")
            for name, value in sorted(ours.items())
            if name not in real or real[name][0] != value]


def expected_source(name: str, installed: set[str]) -> str | None:
    """Where real rosidl's hash of `name` must come from: the wheel of its
    package, our checked-in package, or (None) our typestore's text."""
    package = name.split("/")[0]
    if package == types.OURS:
        return "rosidl from the checked-in package"
    return f"installed {package}" if package in installed else None


def test_every_type_hashes_as_real_rosidl_does(real_hashes: dict[str, Any]) -> None:
    store = types.typestore()
    ours = {name: types.type_hash(name) for name in store.fielddefs}
    real = real_hashes["hashes"]
    assert hash_problems(real, ours) == []
    # every type the bridge sends or takes, and the bag holds, has its package's real
    # definition where a wheel ships that package, our checked-in one for ours
    used = {o.ros_type for o in (*bridge.OUTGOING, bridge.RAW_IMAGE_COMPRESSED)}
    used |= {i.ros_type for i in bridge.INCOMING} | set(action.TOPICS.values())
    used |= {t for entry in rosbag.TABLE for t in entry.ros_types}
    used |= {s.ros_type for s in services.SERVICES} | set(action.SERVICES.values())
    installed = set(real_hashes["packages"])
    wanted = {name: expected_source(name, installed) for name in used}
    assert {name: real[name][1] for name, want in wanted.items()
            if want is not None and real[name][1] != want} == {}
    assert real[NO_WHEEL_SAMPLE][1] == "rosidl from our typestore's definition"
    # the check can fail: a type given another's hash is seen
    broken = dict(ours, **{types.POINT_STAMPED: types.type_hash(types.IMAGE)})
    assert hash_problems(real, broken) != []


# --- CDR of what the bridge publishes ----------------------------------------------


def plain(value: Any) -> Any:
    """A rosbags message as JSON values (rclpy_side.plain's twin)."""
    if dataclasses.is_dataclass(value):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if not f.name.startswith("__") and not f.name.isupper()  # constants
                and f.name != "structure_needs_at_least_one_member"}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, bytes | bytearray):
        return list(value)
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


def _stamp(stamp_ns: int) -> dict[str, int]:
    return {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9}


def intended(ros_type: str, message: m.Message) -> dict[str, Any] | None:
    """The fields a standard type should hold for our `message`, written here from
    the types' definitions (not through our encoder or decoder); None where this
    test does not spell them (our own types, which rclpy cannot load here)."""
    if isinstance(message, m.FacePosition) and ros_type == types.POINT_STAMPED:
        point = message.point
        return {"header": {"stamp": _stamp(message.stamp_ns), "frame_id": message.frame_id},
                "point": {"x": point.x, "y": point.y, "z": point.z}}
    if isinstance(message, m.Image) and ros_type == types.IMAGE:
        return {"header": {"stamp": _stamp(message.stamp_ns), "frame_id": message.frame_id},
                "height": message.height, "width": message.width, "encoding": "bgr8",
                "is_bigendian": 0, "step": message.width * 3, "data": list(message.data)}
    if isinstance(message, m.Image) and ros_type == types.COMPRESSED_IMAGE:
        # a bgr8 frame's JPEG is our encoder's: its bytes as our decoder reads them (None)
        return {"header": {"stamp": _stamp(message.stamp_ns), "frame_id": message.frame_id},
                "format": "jpeg",
                "data": list(message.data) if message.encoding == "jpeg" else None}
    if isinstance(message, m.Bool) and ros_type == types.BOOL:
        return {"data": message.data}
    return None


Item = tuple[str, str, bytes, "dict[str, Any] | None"]
"""(what, ROS type, our CDR, the fields it should hold, or None: as our decoder reads it)."""


def published() -> list[Item]:
    """Every message the bridge publishes, on sample values: each topic, the
    services' responses, the action's status, feedback and replies."""
    by_type = {type(x): x for x in sample_messages()}
    out: list[Item] = []
    for o in (*bridge.OUTGOING, bridge.RAW_IMAGE_COMPRESSED):
        message = by_type[o.topic.type]
        out.append((f"/{o.name} {o.ros_type}", o.ros_type, o.encode(message),
                    intended(o.ros_type, message)))
    reply = m.TriggerReply(success=False, message="nothing plays")
    for s in services.SERVICES:
        want = {"success": False, "message": "nothing plays"} \
            if s.ros_type == types.TRIGGER else None
        out.append((f"/{s.name} response", f"{s.ros_type}_Response",
                    services.reply_to_ros(reply, s), want))
    goals = [action.Goal(uuid=bytes(range(16)), goal_id="g1", stamp_ns=1_700_000_000_123,
                         state="PLAYING", progress=0.5),
             action.Goal(uuid=bytes(16), goal_id="g2", stamp_ns=5, state="SUCCEEDED")]
    infos = [{"goal_id": {"uuid": list(g.uuid)}, "stamp": _stamp(g.stamp_ns)} for g in goals]
    out += [
        ("/play_sound status", action.STATUS, action.encode_status(goals),
         {"status_list": [{"goal_info": infos[0], "status": 2},  # EXECUTING
                          {"goal_info": infos[1], "status": 4}]}),  # SUCCEEDED
        ("/play_sound cancel_goal response", f"{action.CANCEL_GOAL}_Response",
         action.encode_cancel_reply(0, goals), {"return_code": 0, "goals_canceling": infos}),
        ("/play_sound feedback", action.FEEDBACK, action.encode_feedback(goals[0]), None),
        ("/play_sound send_goal response", f"{action.SEND_GOAL}_Response",
         action.encode_send_goal_reply(True, 1_700_000_000_000_000_007), None),
        ("/play_sound get_result response", f"{action.GET_RESULT}_Response",
         action.encode_result(4, "SUCCEEDED", "done"), None)]
    out += [(f"/{x.name} {x.ros_type}", x.ros_type, x.payload, None) for x in hri_samples()]
    return out


def hri_samples() -> list[hri.Sample]:
    """What the ROS4HRI topics carry for a named, engaged person whose direction is
    known: every one of them (the lists, the person's four topics, /tf)."""
    t = 1_700_000_000_000_000_000
    ada = m.Person(id=3, distance_m=1.2, zone="PERSONAL", seen_by="BOTH", zone_since_ns=t,
                   arrived_ns=t, engagement="ENGAGED", engagement_since_ns=t, yaw_rad=0.2,
                   pitch_rad=-0.05, name="Ada Lovelace")
    plan = hri.HriPlanner("camera_front").step(m.PeopleState(stamp_ns=t + 5, people=[ada]))
    assert {x.name.rsplit("/", 1)[-1] for x in plan.samples} == {
        "tracked", "known", "engagement_status", "location_confidence", "anonymous", "alias",
        "tf"}, plan.samples
    return list(plan.samples)


def rclpy_cdr(python: str, folder: Path, items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    (folder / "in.json").write_text(json.dumps(items))
    side(python, "cdr", str(folder / "in.json"), str(folder / "out.json"))
    result: list[dict[str, Any]] = json.loads((folder / "out.json").read_text())
    return result


def ours_decoded(payload: bytes, ros_type: str) -> Any:
    """`payload` read by our checked decoder, as JSON values (or why it refused)."""
    try:
        return plain(convert.deserialize(payload, ros_type))
    except convert.ConvertError as e:
        return f"refused: {e}"


def cdr_problems(python: str, folder: Path, items: list[Item],
                 installed: set[str]) -> tuple[list[str], int]:
    """What real rclpy does otherwise than we with `items`, and how many it could
    check: it must decode our bytes to the values meant (or, where the test does
    not spell them, to those our decoder reads); its own encoding of those values
    must decode with our decoder to the same, and equal our bytes but for CDR
    padding, which Fast-CDR leaves unwritten (whatever the buffer held) and adds
    at the end up to a multiple of 4 bytes.
    That the bytes where the two differ are padding is rclpy's to say: with each
    of them changed in our payload, it still decodes the same values."""
    problems: list[str] = []
    fields = []
    for what, ros_type, payload, meant in items:
        ours = ours_decoded(payload, ros_type)
        want = ours if meant is None else \
            {k: ours[k] if v is None and isinstance(ours, dict) else v for k, v in meant.items()}
        if ours != want:
            problems.append(f"{what}: our decoder reads {ours}, meant {want}")
        fields.append(want)
    got = rclpy_cdr(python, folder, [{"type": t, "cdr": p.hex(), "fields": f}
                                     for (_w, t, p, _m), f in zip(items, fields, strict=True)])
    variants: list[tuple[str, str, Any, bytes]] = []
    for (what, ros_type, payload, _m), want, result in zip(items, fields, got, strict=True):
        if not result["available"]:
            if ros_type.split("/")[0] in installed:
                problems.append(f"{what}: {result['reason']}")
            continue
        if "error" in result:
            problems.append(f"{what}: rclpy: {result['error']}")
            continue
        if result["decoded"] != want:
            problems.append(f"{what}: rclpy decodes {result['decoded']}, ours holds {want}")
        differ: set[int] = set()
        for theirs in (bytes.fromhex(result["reserialized"]),
                       bytes.fromhex(result["from_fields"])):
            if ours_decoded(theirs, ros_type) != want:
                problems.append(f"{what}: our decoder reads rclpy's {theirs.hex()} otherwise")
            if not len(payload) <= len(theirs) <= len(payload) + 3:
                problems.append(f"{what}: rclpy writes {len(theirs)} bytes, we {len(payload)}")
            differ |= {i for i, (a, b) in enumerate(zip(payload, theirs, strict=False)) if a != b}
        if differ:
            bent = bytes(b ^ 0xFF if i in differ else b for i, b in enumerate(payload))
            variants.append((f"{what} (bytes {sorted(differ)} changed)", ros_type, want, bent))
    if variants:
        again = rclpy_cdr(python, folder, [{"type": t, "cdr": p.hex()}
                                           for _w, t, _f, p in variants])
        for (what, _t, want, _p), result in zip(variants, again, strict=True):
            if result.get("decoded") != want:
                problems.append(f"{what}: not padding, rclpy reads "
                                f"{result.get('decoded', result.get('error'))}")
    return problems, sum(bool(r["available"]) for r in got)


def test_rclpy_reads_and_writes_every_message_we_publish_as_we_do(
        python: str, real_hashes: dict[str, Any], tmp_path: Path) -> None:
    items = published()
    installed = set(real_hashes["packages"])
    problems, checked = cdr_problems(python, tmp_path, items, installed)
    assert problems == []
    # the 5 topics of standard types, 3 Trigger replies, 2 of the action, and ROS4HRI's
    # location_confidence, anonymous and alias (hri_msgs and tf2_msgs have no wheel)
    assert checked >= 13
    # the check can fail: one byte of a value changed (the high byte of the point's z)
    what, ros_type, payload, meant = items[0]
    assert ros_type == types.POINT_STAMPED
    bent = payload[:-1] + bytes([payload[-1] ^ 0x40])
    found, _n = cdr_problems(python, tmp_path, [(what, ros_type, bent, meant)], installed)
    assert any("rclpy decodes" in p for p in found), found


def test_the_bridge_takes_the_requests_rclpy_writes(python: str, tmp_path: Path) -> None:
    """The standard requests a ROS 2 client sends (a Trigger, a cancel), as
    rclpy's Fast-CDR writes them (rmw_zenoh_cpp serialises with Fast-CDR too:
    its padding unwritten, the end padded to 4 bytes), read by the bridge's own
    decoders."""
    uuid, stamp_ns = bytes(range(16)), 1_700_000_000_000_000_005
    got = rclpy_cdr(python, tmp_path, [
        {"type": f"{types.TRIGGER}_Request", "cdr": None, "fields": {}},
        {"type": f"{action.CANCEL_GOAL}_Request", "cdr": None, "fields": {
            "goal_info": {"goal_id": {"uuid": list(uuid)}, "stamp": _stamp(stamp_ns)}}}])
    trigger, cancel = (bytes.fromhex(g["from_fields"]) for g in got)
    assert len(trigger) == 8  # one byte of the empty struct, three of padding
    stop = next(s for s in services.SERVICES if s.ros_type == types.TRIGGER)
    assert isinstance(services.request_from_ros(trigger, stop), stop.service.request)
    assert action.decode_cancel(cancel) == (uuid, stamp_ns)


# --- an exported bag ---------------------------------------------------------------


def export(tmp_path: Path) -> tuple[Path, dict[str, m.Message]]:
    """`buddybot bag export --ros2` (in-process) of a recording of every topic once:
    the bag's folder, and the recorded message of each ROS 2 topic."""
    base = time.time_ns()
    found = samples()
    items = [(key, payload, base + i * 10_000_000)
             for i, (key, (_t, payload)) in enumerate(found.items())]
    write_recording(tmp_path / "visit.mcap", items)
    args: argparse.Namespace = cli.build_parser().parse_args(
        ["bag", "export", "--ros2", str(tmp_path / "visit.mcap"), str(tmp_path / "ros")])
    assert int(args.subverb_main(SimpleNamespace(args=args, robot="buddy",
                                                 config=default_config()))) == 0
    recorded = {entry.ros_name: channels.decode(topic, payload)
                for topic, payload in found.values()
                for entry in rosbag.TABLE if entry.topic is topic}
    return tmp_path / "ros", recorded


def test_rclpy_reads_every_message_of_an_exported_bag(
        python: str, real_hashes: dict[str, Any], tmp_path: Path) -> None:
    folder, recorded = export(tmp_path)
    metadata = yaml.safe_load((folder / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    real = real_hashes["hashes"]
    for topic in metadata["topics_with_message_count"]:
        meta = topic["topic_metadata"]
        assert meta["type_description_hash"] == real[meta["type"]][0], meta
    messages: list[Item] = []
    with open(folder / "ros_0.mcap", "rb") as stream:  # mcap's reader, not ours
        for schema, channel, record in make_reader(stream).iter_messages():
            assert schema is not None
            assert channel.metadata["topic_type_hash"] == real[schema.name][0], channel
            source = recorded.get(channel.topic)  # None: a topic named per person, ...
            messages.append((channel.topic, schema.name, bytes(record.data),
                             None if source is None else intended(schema.name, source)))
    assert {e.ros_name for e in rosbag.TABLE} <= {w for w, _n, _d, _m in messages}
    problems, checked = cdr_problems(python, tmp_path, messages,
                                     set(real_hashes["packages"]))
    assert problems == []
    assert checked >= 4  # the face, both images, the audio device
