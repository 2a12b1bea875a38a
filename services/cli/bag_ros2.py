"""`buddybot bag export --ros2` and `bag import`: our recordings to and from rosbag2.

    buddybot bag export --ros2 visit.mcap visit_ros2      # a rosbag2 directory
    buddybot bag export --ros2 visit.mcap small --raw-image compressed
    buddybot bag import ros2_visit visit.mcap             # a rosbag2 directory or .mcap file

The conversion is `ros2/rosbag.py`'s; our recordings are `tools/bag.py`'s;
this module only joins the two (the CLI is the one layer that sees both).

`export` checks the whole recording first, as `play` does (a damaged file
writes nothing), then writes each message of a mapped key on its ROS 2
topic at its recorded time, as the bridge under the same `[ros2]` settings
(`--raw-image` on top) publishes it: the same type and QoS. `import`
walks the ROS 2 file with the bounds every recording gets
(`tools/mcap_records.py`: record, chunk and message sizes checked before
anything is read or unpacked, CRCs), takes only the channels
`rosbag.accept_channel` takes, converts each message with its checks, and
writes a recording `bag play` replays; a message that does not decode is
counted and skipped. A file too large or damaged is refused
whole (exit 1) and the output removed.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from mcap.records import Channel, Message, Schema

from buddybot.contract import channels, keys
from buddybot.ros2 import convert, rosbag
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.overrides import merge
from buddybot.runtime.service import ServiceContext
from buddybot.tools import bag, mcap_records


def _note(text: str) -> None:
    print(f"buddybot bag: {text}", file=sys.stderr)


def export(ctx: ServiceContext) -> int:
    """Write a rosbag2 directory from one of our recordings."""
    args = ctx.args
    recording = bag.open_recording(args.file)
    settings = merge(ctx.config.section(Ros2Settings), args)
    try:
        writer = rosbag.Rosbag2Writer(args.output, settings)
    except rosbag.Ros2BagError as exc:
        raise bag.BagError(str(exc)) from None
    try:
        for item in recording.messages():
            writer.write(item.key, item.topic, channels.decode(item.topic, item.payload),
                         item.log_time_ns)
    except BaseException:
        writer.abort()
        raise
    writer.close()
    for channel in recording.unknown:
        _note(f"skipping {channel.key}: {channel.skipped}")
    for key, why in sorted(writer.stats.skipped.items()):
        _note(f"skipping {key}: {why}")
    if "/raw_image" in writer.stats.per_topic:
        _note(f"/raw_image as {rosbag.live(settings)['raw_image'].ros_type} "
              f"(raw_image = {settings.raw_image!r}, as the bridge publishes it)")
    topics = ", ".join(f"{name} {n}" for name, n in sorted(writer.stats.per_topic.items()))
    print(f"exported {writer.stats.messages} messages on {len(writer.stats.per_topic)} ROS 2 "
          f"topics ({topics or 'none'}) -> {writer.directory}/ (metadata.yaml, "
          f"{writer.file.name})", file=sys.stderr, flush=True)
    return 0


def import_(ctx: ServiceContext) -> int:
    """Write one of our recordings from a ROS 2 MCAP file or rosbag2 directory."""
    args = ctx.args
    try:
        files = rosbag.mcap_files(args.file)
    except rosbag.Ros2BagError as exc:
        raise bag.BagError(str(exc)) from None
    writer = bag.BagWriter(args.output, robot=ctx.robot)
    stats = rosbag.ImportStats()
    try:
        for path in files:
            _import_file(path, writer, stats, args.camera, ctx.robot)
    except BaseException:
        writer.close()
        Path(args.output).unlink(missing_ok=True)
        raise
    writer.close()
    for topic, why in sorted(stats.skipped.items()):
        _note(f"skipping {topic}: {why}")
    for topic, n in sorted(stats.malformed.items()):
        _note(f"{n} messages on {topic} refused (first: {stats.first_error[topic]})")
    if not stats.messages:
        _note(f"warning: nothing imported: no message of {args.file} is on a ROS 2 topic "
              "BuddyBot takes (see docs/recording.md)")
    refused = sum(stats.malformed.values())
    extra = f", {refused} refused" if refused else ""
    print(f"imported {stats.messages} messages from {len(stats.per_topic)} ROS 2 topics"
          f"{extra} -> {args.output}", file=sys.stderr, flush=True)
    return 0


def _import_file(path: Path, writer: bag.BagWriter, stats: rosbag.ImportStats,
                 camera: str, robot: str) -> None:
    schemas: dict[int, Schema] = {}
    taken: dict[int, rosbag.Accepted | str] = {}
    state = mcap_records.Walk()
    try:
        stream = open(path, "rb")  # noqa: SIM115 (closed below)
    except OSError as exc:
        raise bag.BagError(f"{path}: cannot read: {exc.strerror or exc}") from None
    with stream:
        size = os.fstat(stream.fileno()).st_size
        try:
            for record in mcap_records.walk(stream, size, state):
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    taken[record.id] = found = _accept(record, schemas.get(record.schema_id))
                    if isinstance(found, str):
                        stats.skipped.setdefault(record.topic[:200], found)
                elif isinstance(record, Message):
                    _take(record, taken, writer, stats, camera, robot)
        except mcap_records.TooLarge as exc:
            raise bag.BagError(f"{path}: refused: {exc}") from None
        except mcap_records.Damaged as exc:
            raise bag.BagError(f"{path}: damaged ({exc}); refusing to import it") from None
        stream.seek(max(0, size - len(mcap_records.MAGIC)))
        ends = stream.read(len(mcap_records.MAGIC)) == mcap_records.MAGIC
    if not state.data_end or not ends:
        raise bag.BagError(f"{path}: truncated (no end of data or no footer): its recorder "
                           "was killed, or a copy stopped half-way; refusing to import it")


def _accept(channel: Channel, schema: Schema | None) -> rosbag.Accepted | str:
    if schema is None:
        return rosbag.accept_channel(channel.topic, "", "", b"", channel.message_encoding)
    return rosbag.accept_channel(channel.topic, schema.name, schema.encoding, schema.data,
                                 channel.message_encoding)


def _take(record: Message, taken: dict[int, rosbag.Accepted | str], writer: bag.BagWriter,
          stats: rosbag.ImportStats, camera: str, robot: str) -> None:
    found = taken.get(record.channel_id)
    if found is None:
        raise mcap_records.Damaged(f"a message on channel {record.channel_id}, "
                                   "which no record declares")
    if isinstance(found, str):
        return
    name = found.entry.ros_name
    try:
        message = rosbag.from_ros(found.entry, found.ros_type, record.data, record.log_time)
    except convert.ConvertError as exc:
        stats.malformed[name] = stats.malformed.get(name, 0) + 1
        stats.first_error.setdefault(name, str(exc)[:200])
        return
    key = keys.absolute(robot, rosbag.relative_key(found.entry, message, camera))
    writer.write(key, found.entry.topic.codec.encode(message), record.log_time)
    stats.messages += 1
    stats.per_topic[name] = stats.per_topic.get(name, 0) + 1
