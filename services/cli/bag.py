"""`buddybot bag record|play|info`: record the robot's keys to MCAP, replay them, describe a file.

    buddybot bag record -o visit.mcap [--duration S] [KEY ...] [--images]
    buddybot bag play visit.mcap [--rate R] [--loop] [--start S] [--keys KEY ...] [--robot ID]
    buddybot bag info visit.mcap [--json]
    buddybot bag recover cut.mcap -o visit.mcap
    buddybot bag export --ros2 visit.mcap visit_ros2 [--raw-image raw|compressed]
    buddybot bag import ros2_visit visit.mcap [--camera NAME]

`record` writes one MCAP channel per concrete key of the catalogue's
topics (images only with `--images`, JPEG) or of the KEYs given, and the
file is always finished, whatever ends it. `play` checks the whole file
first (a damaged file is refused, nothing published), then republishes
each recorded payload on its key (`--robot` moves it to another robot) at
the recorded pace divided by `--rate`; latched keys are published as the
services publish them. `recover` copies what a killed recorder or a full
disk left into a new, finished file. `export --ros2` writes a rosbag2
directory of the original robot's ROS 2 topics; `import` is the way back
(cli/bag_ros2.py, ros2/rosbag.py). How: tools/bag.py and docs/recording.md.

Exit status: 0 done (or stopped with Ctrl-C), 1 an unreadable file or no
router, 2 bad usage.
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import statistics
import sys
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from buddybot.cli import subverbs
from buddybot.cli.subverbs import SubVerb
from buddybot.contract import channels, keys
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime import options
from buddybot.runtime.errors import UsageError
from buddybot.runtime.node import Node, Publisher
from buddybot.runtime.overrides import settings_option
from buddybot.runtime.service import ServiceContext
from buddybot.runtime.session import CONNECT_TIMEOUT_S, RouterUnreachable, zenoh_config
from buddybot.tools import bag, bag_recover, probing
from buddybot.tools.bag_record import Progress, Recorder

HELP = "record the robot's keys to an MCAP file, replay one, or describe one"
PLAY_NODE = "bag-play"
PROGRESS_S = 1.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    subverbs.add_subverbs(parser, SUBVERBS, metavar="ACTION")


def main(ctx: ServiceContext) -> int:
    return subverbs.run(ctx)


# --- record -------------------------------------------------------------------------


def record_keys(robot: str, selected: list[str], images: bool) -> list[tuple[str, bool]]:
    """The key expressions to subscribe to, each with whether it needs history
    (a latched topic's current value). UsageError for a key nothing matches."""
    wanted: list[tuple[str, bool]] = []
    if not selected:
        wanted = [(keys.absolute(robot, t.wildcard()), t.latched) for t in keys.TOPICS
                  if not channels.is_image(t)]
    for text in selected:
        key = keys.absolute(robot, text)
        topics = [e for e in probing.catalogue_matches(key) if isinstance(e, keys.Topic)]
        if not topics:
            raise UsageError(f"{text}: matches no topic of the catalogue (see `buddybot keys`)")
        wanted.append((key, any(t.latched for t in topics)))
    if images:
        image = keys.absolute(robot, keys.CAMERA_IMAGE.wildcard())
        if all(key != image for key, _ in wanted):
            wanted.append((image, False))
    return wanted


def _megabytes(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def _add_record(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("keys", nargs="*", metavar="KEY",
                        help="keys to record (relative or absolute, wildcards allowed; "
                             "default: every topic but images)")
    parser.add_argument("-o", "--output", metavar="FILE", required=True,
                        help="the MCAP file to write")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop after S seconds (default: at Ctrl-C or SIGTERM)")
    parser.add_argument("--images", action="store_true",
                        help="also record camera/*/image (JPEG-compressed)")
    options.add_timeout_argument(
        parser, None, "here only the connection (--duration ends a recording)")


def record(ctx: ServiceContext) -> int:
    """Record until Ctrl-C, SIGTERM or --duration; the file is always finished."""
    args = ctx.args
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    wanted = record_keys(ctx.robot, args.keys, args.images)
    tty = sys.stderr.isatty()
    with ctx.probe(args.timeout) as node:
        recorder = Recorder(bag.BagWriter(args.output, robot=ctx.robot))

        def on_sample(key: str, payload: bytes, _encoding: str) -> None:
            recorder.offer(key, payload, time.time_ns())  # never blocks Zenoh's thread

        # Latched keys as services take them (history, and recovery of a value
        # dropped under congestion), so a recording misses no state.
        subscriptions = [node.subscribe_raw(key, on_sample, recover=latched)
                         for key, latched in wanted]
        started = time.monotonic()
        end = probing.deadline(args.duration)
        next_line = started + PROGRESS_S
        try:
            while not ctx.stop.is_set() and recorder.error is None:
                now = time.monotonic()
                if now >= end:
                    break
                if tty and now >= next_line:
                    next_line += PROGRESS_S
                    _progress(recorder, now - started)
                wake = min(end, next_line) if tty else min(end, now + 1.0)
                ctx.stop.wait(max(0.0, wake - now))
        finally:
            for sub in subscriptions:  # no sample after this: the queue only drains
                sub.close()
            final = recorder.close()
            elapsed = time.monotonic() - started
        if final.written == 0 and recorder.error is None and not ctx.stop.is_set():
            print(f"buddybot bag: warning: nothing recorded: "
                  f"{probing.silence_reason(node, keys.absolute(ctx.robot, '**'))}",
                  file=sys.stderr)
    if tty:
        print(file=sys.stderr)
    if recorder.error is not None:
        return _failed(args.output, recorder.error, final, elapsed)
    extra = "".join(f", {n} {what}" for n, what in ((final.dropped, "dropped (queue full)"),
                                                     (final.malformed, "malformed (skipped)"),
                                                     (final.unknown, "not in the catalogue"))
                    if n)
    keys_seen = len(recorder.writer.stats.per_key)
    print(f"recorded {final.written} messages on {keys_seen} keys, {_megabytes(final.bytes)}, "
          f"{elapsed:.1f} s{extra} -> {args.output}", file=sys.stderr, flush=True)
    return 0


def _failed(output: str, error: BaseException, final: Progress, elapsed: float) -> int:
    """The summary of a recording the disk stopped: what the file really holds
    (read back, up to its last complete chunk), not what was handed to the writer."""
    reason = getattr(error, "strerror", None) or str(error) or type(error).__name__
    try:
        found = bag_recover.scan(output)
    except bag.BagError as exc:
        print(f"buddybot bag: writing {output} failed after {final.written} messages "
              f"({reason}); nothing readable: {exc}", file=sys.stderr, flush=True)
        return 1
    print(f"recorded {found.messages} of {final.written} messages, "
          f"{_megabytes(found.readable_bytes)} readable of {_megabytes(found.size)} written, "
          f"{elapsed:.1f} s -> {output}", file=sys.stderr)
    print(f"buddybot bag: writing {output} failed: {reason}; the file has no summary: "
          f"`buddybot bag recover {output} -o FILE` copies its {found.messages} messages "
          "into a finished file", file=sys.stderr, flush=True)
    return 1


def _progress(recorder: Recorder, elapsed: float) -> None:
    p = recorder.progress()
    drops = f", {p.dropped} dropped" if p.dropped else ""
    print(f"\rrecording: {p.written} messages, {_megabytes(p.bytes)}, {elapsed:.0f} s{drops}  ",
          end="", file=sys.stderr, flush=True)


# --- play ---------------------------------------------------------------------------


@dataclass
class PlayStats:
    """What a replay did, and how late each message left against its schedule."""

    played: int = 0
    loops: int = 0
    late_ms: collections.deque[float] = field(
        default_factory=lambda: collections.deque(maxlen=100_000))
    """The latest lateness figures (bounded: a replay may loop for hours)."""

    def lateness(self) -> str:
        if not self.late_ms:
            return ""
        ordered = sorted(self.late_ms)
        p95 = ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))]
        return f"; late vs schedule p50 {statistics.median(ordered):.2f} ms, p95 {p95:.2f} ms"


def _add_play(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE")
    parser.add_argument("--rate", type=float, default=1.0, metavar="R",
                        help="play R times as fast (default 1)")
    parser.add_argument("--loop", action="store_true",
                        help="start again at the end, until stopped")
    parser.add_argument("--start", type=float, default=0.0, metavar="S",
                        help="skip the first S seconds of the recording")
    parser.add_argument("--keys", nargs="+", action="extend", default=[], metavar="KEY",
                        help="replay only these keys (relative or absolute, wildcards allowed)")
    parser.add_argument("--wait", type=float, default=1.0, metavar="S",
                        help="wait up to S seconds for subscribers before the first "
                             "message, and S seconds after the last when latched keys "
                             "were played (their cache answers late subscribers)")
    options.add_timeout_argument(parser, None,
                                 "here only the connection (a replay lasts its file)")


def play(ctx: ServiceContext) -> int:
    """Check the whole file, then replay it; nothing is published from a bad file."""
    args = ctx.args
    path = args.file
    if args.rate <= 0:
        raise UsageError("--rate must be positive")
    if args.start < 0:
        raise UsageError("--start must be 0 or more")
    recording = bag.open_recording(path)  # BagError (exit 1) before any connection
    only = [_on_any_robot(k) for k in args.keys]
    selected = recording.selected(only)
    if args.keys and not selected:
        raise UsageError(f"--keys {' '.join(args.keys)}: no channel of {path} matches")
    for channel in recording.unknown:
        print(f"buddybot bag: skipping {channel.key}: {channel.skipped}", file=sys.stderr)
    info = recording.info
    robot = args.robot  # the common option as given: None keeps the recorded robots
    start_ns = info.start_ns + round(args.start * 1e9) if args.start else None
    if start_ns is not None and start_ns > info.end_ns:
        raise UsageError(f"--start {args.start:g}: the recording lasts {info.duration_s:.1f} s")
    recorded = info.metadata.get("robot", "")  # the file's word: used only when valid
    node = _play_node(ctx, robot or (recorded if keys.valid_robot_id(recorded) else ctx.robot))
    stats = PlayStats()
    tty = sys.stderr.isatty()
    with node:
        publishers: dict[str, Publisher[Any]] = {
            c.key: node.publisher_on(c.topic, bag.with_robot(c.key, robot))
            for c in selected if c.topic is not None}
        _wait_for_subscribers(node, list(publishers.values()), args.wait, ctx)
        while not ctx.stop.is_set():
            _play_once(recording, publishers, start_ns, only, args.rate, ctx, stats, tty)
            stats.loops += 1
            if not args.loop:
                break
        stopped = " (stopped)" if ctx.stop.is_set() else ""  # closing the node sets it too
        time.sleep(0.1)  # let the last puts leave before the session closes
        if not stopped and any(p.topic.latched for p in publishers.values()):
            # The latched values' cache dies with the player: a subscriber whose
            # history query is still on its way (a busy machine) gets it meanwhile.
            ctx.stop.wait(max(0.0, args.wait))
    if tty:
        print(file=sys.stderr)
    loops = f" in {stats.loops} loops" if args.loop else ""
    print(f"played {stats.played} messages on {len(publishers)} keys{loops}{stopped}"
          f"{stats.lateness()}", file=sys.stderr, flush=True)
    return 0


def _on_any_robot(key: str) -> str:
    """A relative `--keys` KEY matches that key of whichever robot was recorded."""
    key = key.strip("/")
    if key == keys.PREFIX_ROOT or key.startswith(f"{keys.PREFIX_ROOT}/"):
        return key
    return f"{keys.PREFIX_ROOT}/*/{key}"


def _play_node(ctx: ServiceContext, robot: str) -> Node:
    """The player's node: seen by `nodes` (it publishes on the robot's keys), but
    giving up on the router after --timeout like a probe instead of waiting."""
    limit = ctx.args.timeout if ctx.args.timeout and ctx.args.timeout > 0 \
        else CONNECT_TIMEOUT_S
    config = zenoh_config(connect=ctx.connect, base_file=ctx.config.zenoh.config_file,
                          connect_timeout_s=limit)
    if getattr(ctx.args, "log_level", "INFO") == "INFO":  # its "node up" line is noise here
        logging.getLogger(f"buddybot.{PLAY_NODE}").setLevel(logging.WARNING)
    try:
        return Node(PLAY_NODE, robot=robot, connect=ctx.connect, config=config,
                    stop_event=ctx.stop)
    except RouterUnreachable as exc:
        raise RouterUnreachable(f"{exc} (gave up after {limit:g} s)") from None


def _wait_for_subscribers(node: Node, publishers: list[Publisher[Any]], wait: float,
                          ctx: ServiceContext) -> None:
    """Give discovery a moment, so the first messages reach the subscribers that
    exist. Latched keys are waited for too: their cache dies with the player,
    so a put made before the router told us of a subscriber is lost for good.
    An advanced (latched) publisher cannot say whether it is matched, so a
    plain probe publisher on the same key answers for it."""
    probes = [node.raw_publisher(p.key, p.topic.encoding) for p in publishers
              if p.topic.latched]
    pending = [p for p in publishers if not p.topic.latched] + probes
    try:
        end = time.monotonic() + max(0.0, wait)
        while time.monotonic() < end and not ctx.stop.is_set():
            if all(p.has_subscribers() for p in pending):
                return
            ctx.stop.wait(0.02)
    finally:
        for probe in probes:
            probe.close()


def _play_once(recording: bag.Recording, publishers: dict[str, Publisher[Any]],
               start_ns: int | None, only: list[str], rate: float, ctx: ServiceContext,
               stats: PlayStats, tty: bool) -> None:
    """One pass over the file at the recorded pace (absolute schedule: no drift)."""
    t0 = time.monotonic()
    first: int | None = None
    next_line = t0 + PROGRESS_S
    total = recording.info.duration_s / rate
    for item in recording.messages(start_ns=start_ns, only=only):
        if first is None:
            first = item.log_time_ns
            t0 = time.monotonic()
        due = t0 + bag.schedule_s(item.log_time_ns, first, rate)
        delay = due - time.monotonic()
        if delay > 0 and ctx.stop.wait(delay):
            return
        if ctx.stop.is_set():
            return
        publishers[item.key].put_bytes(item.payload)
        stats.late_ms.append((time.monotonic() - due) * 1e3)
        stats.played += 1
        if tty and time.monotonic() >= next_line:
            next_line += PROGRESS_S
            print(f"\rplaying: {time.monotonic() - t0:.0f} / {total:.0f} s, "
                  f"{stats.played} messages  ", end="", file=sys.stderr, flush=True)


# --- info ---------------------------------------------------------------------------


def _time(ns: int) -> str:
    if ns <= 0:
        return "-"
    moment = datetime.fromtimestamp(ns / 1e9, UTC)
    return f"{moment:%Y-%m-%d %H:%M:%S}.{ns % 1_000_000_000 // 1_000_000:03d} UTC ({ns})"


def _add_info(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="FILE")
    options.add_json_argument(parser)


def info(ctx: ServiceContext) -> int:
    return print_info(ctx.args.file, as_json=ctx.args.json)


def print_info(path: str, *, as_json: bool) -> int:
    """Print a recording's summary, like `ros2 bag info` (reads the summary only)."""
    summary = bag.read_info(path)
    if as_json:
        print(json.dumps(summary.as_json(), indent=2))
        return 0
    meta = summary.metadata
    lines = [
        f"File:       {summary.path}",
        f"Size:       {_megabytes(summary.size)} ({summary.compression})",
        f"Robot:      {meta.get('robot', '?')} (buddybot {meta.get('version', '?')})",
        f"Duration:   {summary.duration_s:.3f} s",
        f"Start:      {_time(summary.start_ns)}",
        f"End:        {_time(summary.end_ns)}",
        f"Messages:   {summary.messages}",
        f"Channels:   {len(summary.channels)}",
    ]
    width = max((len(c.key) for c in summary.channels), default=0)
    schema_width = max((len(c.schema) for c in summary.channels), default=0)
    for c in summary.channels:
        note = "" if not c.skipped else f"  (not replayed: {c.skipped})"
        lines.append(f"  {c.key:<{width}}  {c.schema:<{schema_width}}  {c.count:>7} msgs  "
                     f"{c.rate_hz(summary.duration_s):7.2f} Hz{note}")
    print("\n".join(lines))
    return 0


# --- recover ------------------------------------------------------------------------


def _add_recover(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="IN", help="a recording cut short (killed, disk full)")
    parser.add_argument("-o", "--output", metavar="OUT", required=True,
                        help="the finished recording to write")


def recover(ctx: ServiceContext) -> int:
    """Copy a cut recording's complete records into a finished file."""
    args = ctx.args
    found = bag_recover.recover(args.file, args.output)
    cut = (f", {found.cut_bytes} bytes after the last complete chunk cut"
           if found.cut_bytes and not found.finished else "")
    print(f"recovered {found.messages} messages, {_megabytes(found.readable_bytes)} of "
          f"{_megabytes(found.size)}{cut} -> {args.output}", file=sys.stderr, flush=True)
    return 0


# --- export / import (ROS 2) ------------------------------------------------------------


def _add_export(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ros2", action="store_true", required=True,
                        help="write a rosbag2 directory (the one format there is)")
    parser.add_argument("file", metavar="IN", help="one of our recordings")
    parser.add_argument("output", metavar="OUT",
                        help="the rosbag2 directory to write (new or empty): "
                             "OUT/metadata.yaml and OUT/OUT_0.mcap")
    settings_option(parser, "--raw-image", struct=Ros2Settings, field="raw_image",
                    help="/raw_image as the bridge publishes it: sensor_msgs/msg/Image "
                         "(`raw`, bgr8, the recorded JPEG decoded) or CompressedImage "
                         "(`compressed`, the JPEG as recorded)")


def export(ctx: ServiceContext) -> int:
    from buddybot.cli import bag_ros2  # rosbags and numpy only for this action

    return bag_ros2.export(ctx)


def _add_import(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", metavar="IN",
                        help="a ROS 2 recording: an MCAP file or a rosbag2 directory")
    parser.add_argument("output", metavar="OUT", help="the recording to write")
    parser.add_argument("--camera", default="front", metavar="NAME",
                        help="the camera whose keys /face_position and /raw_image "
                             "become (default front)")


def import_(ctx: ServiceContext) -> int:
    from buddybot.cli import bag_ros2  # rosbags and numpy only for this action

    if not keys.valid_robot_id(ctx.args.camera):
        raise UsageError(f"--camera {ctx.args.camera!r}: not a valid name")
    return bag_ros2.import_(ctx)


SUBVERBS = (
    SubVerb("record", "record the robot's keys to an MCAP file", _add_record, record),
    SubVerb("play", "replay an MCAP file on the robot's keys", _add_play, play),
    SubVerb("info", "describe an MCAP file: duration, channels, rates", _add_info, info),
    SubVerb("recover", "copy what a killed recorder left into a finished MCAP file",
            _add_recover, recover),
    SubVerb("export", "write a recording as a rosbag2 directory (--ros2) for ROS 2 tools",
            _add_export, export),
    SubVerb("import", "turn a ROS 2 MCAP recording of the robot's topics into a recording",
            _add_import, import_),
)
