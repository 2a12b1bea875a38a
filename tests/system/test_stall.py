"""A stalled reader must never stall the bus.

Each service in turn is frozen with SIGSTOP while a burst floods a key it
reads and an audio goal makes state traffic flow towards it. The sensor
streams that do not pass through the frozen service (radar frames, camera
images) must keep arriving at a healthy subscriber without gaps over
a bound, a goal's status must reach a
healthy subscriber at once, and the frozen service must come back once it is
resumed.

With congestion control BLOCK on state keys and Zenoh's default 5 s
`wait_before_close`, radar frames stop for 4-5 s here.
"""

from __future__ import annotations

import itertools
import signal
import sys
import threading
import time
from pathlib import Path

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Process, retry_until

from ..conftest import TIMING
from .robot import BASE_SERVICES, Spawn, start_radar, start_robot, wait_nodes

pytestmark = [pytest.mark.integration,  # a router and the robot's processes
              TIMING]  # gaps under a bound

MAX_GAP_S = 2.0
"""The bound asserted here. The target is 200 ms (met on a quiet machine, see
docs/core.md); with the rest of the suite running beside it on two cores, CPU
noise alone makes gaps of up to about a second (1.07 s seen), while the stall
this test guards against lasted 4-5 s and left a goal's status undelivered."""
BURST_S = 4.0

# What floods each service: a key it subscribes to.
BURST_KEY = {
    "controller": keys.FACE.key(camera="front"),
    "eyes": keys.EYE_CONTROL.key(),
    "eye-renderer": keys.EYES_DIRECTION.key(),
    "face-detector": keys.CAMERA_IMAGE.key(camera="front"),
    "radar-presence": keys.RADAR_FRAMES.key(device="burst"),
    "audio": keys.DEVICE_FREE.key(),
    "audio-player": keys.PLAY_SOUND_STATUS.key(),
    "camera": keys.PLAY_SOUND_STATUS.key(),
}

BURSTER = """
import sys, time, zenoh
endpoint, key, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", '["%s"]' % endpoint)
conf.insert_json5("scouting/multicast/enabled", "false")
payload = b"\\xff" * 4096  # garbage: counted as malformed once the reader runs again
with zenoh.open(conf) as session:
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
    start = time.monotonic()
    end = start + seconds
    sent = 0
    half = False
    while time.monotonic() < end:
        if not half and time.monotonic() > start + seconds / 2:
            print("half", flush=True)  # the frozen reader's queues are full by now
            half = True
        for _ in range(20):
            pub.put(payload)
        sent += 20
        time.sleep(0.01)  # ~2000 puts/s, ~8 MB/s
    print("sent", sent, flush=True)
"""


class Arrivals:
    """Arrival times of one key, recorded without decoding (cheap, in Zenoh's thread)."""

    def __init__(self, node: Node, key: str) -> None:
        self.times: list[float] = []
        self.payloads: list[bytes] = []
        self._lock = threading.Lock()
        self._sub = node.subscribe_raw(key, self._on)

    def _on(self, _key: str, payload: bytes, _encoding: str) -> None:
        with self._lock:
            self.times.append(time.monotonic())
            # Kept aligned with `times`; only small payloads are worth keeping.
            self.payloads.append(payload if len(payload) < 1024 else b"")

    def first_containing(self, text: bytes, since: float) -> float | None:
        """Arrival time of the first (small) sample after `since` containing `text`."""
        with self._lock:
            return next((t for t, p in zip(self.times, self.payloads, strict=False)
                         if t >= since and text in p), None)

    def max_gap(self, start: float, end: float) -> float:
        """Longest time without an arrival within [start, end]."""
        with self._lock:
            inside = [t for t in self.times if start <= t <= end]
        points = [start, *inside, end]
        return max(b - a for a, b in itertools.pairwise(points))

    def close(self) -> None:
        self._sub.close()


def test_a_stalled_service_never_stalls_the_other_streams(
    probe: Node, spawn: Spawn, tmp_path: Path, endpoint: str
) -> None:
    procs = start_robot(spawn, tmp_path, renderer=True)
    procs["radar-bridge"] = start_radar(spawn, "visit")
    names = [*BASE_SERVICES, "camera", "radar-bridge", "eye-renderer"]
    wait_nodes(probe, names)
    streams = {
        "radar-bridge": Arrivals(probe, probe.key(keys.RADAR_FRAMES, device="0")),
        "camera": Arrivals(probe, probe.key(keys.CAMERA_IMAGE, camera="front")),
    }
    retry_until(lambda: all(len(s.times) > 5 for s in streams.values()), 60, 0.2,
                "radar frames and camera images flowing")
    statuses = Arrivals(probe, probe.key(keys.PLAY_SOUND_STATUS))
    report: list[str] = []
    failures: list[str] = []
    try:
        for victim, burst_key in BURST_KEY.items():
            proc = procs[victim]
            proc.send_signal(signal.SIGSTOP)
            start = time.monotonic()
            burster = Process(
                [sys.executable, "-c", BURSTER, endpoint, keys.absolute("buddy", burst_key),
                 str(BURST_S)], f"burst-{victim}")
            try:
                # State traffic towards the frozen reader once its queues are full
                # (goal statuses, device_free): what used to block the router.
                burster.wait_for_output("half", timeout=BURST_S + 30)
                asked = time.monotonic()
                replies = list(probe.query(
                    probe.key(keys.PLAY_SOUND), b'{"sound": "greeting"}', timeout=5))
                burster.wait_for_output("sent", timeout=BURST_S + 30)
            finally:
                burster.stop()
            end = time.monotonic() + 3.0
            retry_until(lambda end=end: time.monotonic() >= end, 5, 0.05)
            proc.send_signal(signal.SIGCONT)
            gaps = {name: s.max_gap(start, end) for name, s in streams.items()
                    if name != victim}
            goal = None
            if replies and replies[0].ok:
                goal = msgspec.json.decode(replies[0].payload, type=m.PlaySoundReply)
            if victim not in ("audio", "audio-player") and goal is not None and goal.goal_id:
                # The goal's status reaches a healthy subscriber at once, whoever is frozen.
                status_at = retry_until(
                    lambda goal=goal, asked=asked: statuses.first_containing(
                        goal.goal_id.encode(), asked), 20, 0.05,
                    "the goal's status")
                gaps["goal status"] = status_at - asked
            report.append(f"{victim:<14} " + "  ".join(
                f"{name} max gap {gap * 1000:.0f} ms" for name, gap in gaps.items())
                + f"  goal replies {len(replies)}")
            failures += [f"{victim} frozen: {name} stopped for {gap * 1000:.0f} ms"
                         for name, gap in gaps.items() if gap > MAX_GAP_S]
            # The frozen service comes back (its link may have been closed meanwhile).
            retry_until(lambda victim=victim: victim in probe.node_instances(timeout=1.0),
                        30, 0.3, f"{victim} back after SIGCONT")
        print("\n".join(report))
        assert not failures, "\n".join([*failures, *report])
        for name, proc in procs.items():
            assert proc.alive(), f"{name} died:\n{proc.output()[-3000:]}"
    finally:
        for proc in procs.values():
            proc.send_signal(signal.SIGCONT)
        for stream in [*streams.values(), statuses]:
            stream.close()
