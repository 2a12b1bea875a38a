"""Network faults between hosts: cut links, slow and lossy links.

The eye screen and the camera host each live in a network namespace this test
makes, with the shipped TLS + access-control profile (deploy/zenoh/), real
`buddybot` services inside and the router outside, as on a robot spread over
several computers. Then the cable is pulled:

* cut for 10 s (`ip link set down` on the host's end) and plugged back: the eye
  page must show the newest expression and lids, and the camera host's images and
  faces must flow again, within a second of the link coming back;
* the same with a silent cut (every frame lost, the link still "up", like netem
  loss 100 %): within SILENT_RECOVERY_S, TCP's SYN retransmission being the floor;
* 100 ms delay and 5 % loss each way: the gaze must keep flowing, and a new session
  still opens over such a link.

tc netem is not in every kernel (it is missing on the development machine), so the
slow link is two TAP devices joined by `LinkEmulator`, a forwarding thread that
delays and drops Ethernet frames: the kernels on both sides still run real TCP and
TLS over it. Recovery figures are printed (`pytest -s`) and quoted in
docs/deploy.md, "Network faults". Skipped where namespaces cannot be made.
"""

from __future__ import annotations

import contextlib
import fcntl
import heapq
import itertools
import json
import os
import random
import select
import statistics
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    LOOPBACK,
    Process,
    buddybot_argv,
    free_port,
    retry_until,
    wait_port,
)
from tests.conftest import TIMING
from tests.deploy.conftest import (
    HOSTS,
    ZENOH_DIR,
    HostProfile,
    Namespace,
    ip,
    make_certs,
    skip_without_namespaces,
    veth_namespace,
)

pytestmark = TIMING  # network namespaces, recovery times under a bound

CUT_S = 10.0  # how long the cable stays out
RECOVERY_S = 1.0  # the promise: state right again this long after the link is back
SILENT_RECOVERY_S = 2.0
"""The same after a silent outage (every frame lost, carrier up): a connection attempt
begun just before the link came back lost its TCP SYN, and Linux sends the next one
1 s later; nothing in Zenoh's or BuddyBot's hands is faster than that. Measured
0.1-1.0 s (docs/deploy.md); 2 s leaves room for a loaded machine."""
LEASE_MS = 3000  # what the shipped profiles announce (transport/link/tx/lease)
WAIT_BEFORE_CLOSE_US = 100_000
OPEN_TIMEOUT_MS = 1500  # clients: one connection attempt, TCP + TLS + Zenoh handshake
MAX_MESSAGE_BYTES = 16 * 1024 * 1024
GAZE_PERIOD_S = 0.05  # the robot's gaze rate in these tests: 20 Hz


# --- the profiles carry the limits (no processes) -------------------------------------


def _value(name: str, path: str) -> Any:
    return json.loads(zenoh.Config.from_file(str(ZENOH_DIR / name)).get_json(path))


@pytest.mark.parametrize("name", sorted(p.name for p in ZENOH_DIR.glob("*.json5")))
def test_profile_sets_the_network_fault_limits(name: str) -> None:
    """Read back through Zenoh's own parser, so a misplaced key (Zenoh would take
    its default) fails here."""
    tx = "transport/link/tx"
    assert _value(name, f"{tx}/queue/congestion_control/block/wait_before_close") == \
        WAIT_BEFORE_CLOSE_US, "a stalled link must be closed after 0.1 s, not 5 s"
    assert _value(name, "transport/link/rx/max_message_size") == MAX_MESSAGE_BYTES
    assert _value(name, f"{tx}/lease") == LEASE_MS
    assert _value(name, f"{tx}/keep_alive") == 4
    if name != "router.json5":  # the router dials nobody
        assert _value(name, "transport/unicast/open_timeout") == OPEN_TIMEOUT_MS


def test_every_host_has_a_profile() -> None:
    assert {p.stem for p in ZENOH_DIR.glob("*.json5")} == {*HOSTS, "router"}


# --- helpers: processes, a page probe, arrival times --------------------------------------



# Runs inside the eye screen's namespace: the eye page's WebSocket as a browser would
# read it, one line per message: "<monotonic> <wall ns> <topic> <msg json>".
PAGE_PROBE = """
import asyncio, json, sys, time
import aiohttp

async def main(url, seconds):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            async with asyncio.timeout(end - time.monotonic()):
                async with aiohttp.ClientSession() as http:
                    async with http.ws_connect(url) as ws:
                        async for msg in ws:
                            if msg.type != aiohttp.WSMsgType.TEXT:
                                break
                            data = json.loads(msg.data)
                            for item in data if isinstance(data, list) else [data]:
                                print(time.monotonic(), time.time_ns(), item.get("topic"),
                                      json.dumps(item.get("msg")), flush=True)
        except Exception as exc:
            print(time.monotonic(), time.time_ns(), "error", json.dumps(repr(exc)), flush=True)
        await asyncio.sleep(0.2)

asyncio.run(main(sys.argv[1], float(sys.argv[2])))
"""


@dataclass
class PageEvent:
    t: float  # monotonic (shared by every namespace of this machine)
    wall_ns: int
    topic: str
    msg: Any


class PageProbe:
    """What an eye page received, read from the probe process's log."""

    def __init__(self, proc: Process) -> None:
        self.proc = proc

    def events(self) -> list[PageEvent]:
        found: list[PageEvent] = []
        for line in self.proc.output().splitlines():
            parts = line.split(" ", 3)
            if len(parts) == 4:
                with contextlib.suppress(ValueError):
                    found.append(PageEvent(float(parts[0]), int(parts[1]), parts[2],
                                           json.loads(parts[3])))
        return found

    def first(self, topic: str, match: Callable[[Any], bool], after: float = 0.0,
              timeout: float = 60.0) -> PageEvent:
        """The first `topic` message matching `match` received after `after`."""

        def look() -> PageEvent | None:
            return next((e for e in self.events() if e.topic == topic and e.t >= after
                         and isinstance(e.msg, dict) and match(e.msg)), None)

        return retry_until(look, timeout, 0.05, what=f"{topic} on the eye page")


def longest_gap(times: list[float], t0: float, t1: float) -> float:
    """Longest stretch of [t0, t1] without one of `times` (the ends count as times)."""
    points = [t0, *sorted(t for t in times if t0 <= t <= t1), t1]
    return max(b - a for a, b in itertools.pairwise(points))


@dataclass
class Arrivals:
    """Arrival times (monotonic) and stamps of one topic at a node, and how long
    each sample took from its stamp (the sender's wall clock, this host's)."""

    times: list[tuple[float, int]] = field(default_factory=list)
    delays: list[tuple[float, float]] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on(self, msg: Any, _key: str) -> None:
        with self.lock:
            now = time.monotonic()
            self.times.append((now, int(msg.stamp_ns)))
            self.delays.append((now, (m.now_ns() - int(msg.stamp_ns)) / 1e9))

    def first_after(self, t: float, stamp_after_ns: int = 0) -> float | None:
        with self.lock:
            return next((a for a, s in self.times if a >= t and s >= stamp_after_ns), None)

    def longest_delay(self, t0: float, t1: float) -> float:
        """The longest a sample that arrived in [t0, t1] was on its way."""
        with self.lock:
            return max((d for a, d in self.delays if t0 <= a <= t1), default=0.0)

    def longest_gap(self, t0: float, t1: float) -> float:
        """Longest time without an arrival in [t0, t1] (the ends count as arrivals)."""
        with self.lock:
            return longest_gap([a for a, _ in self.times], t0, t1)

    def between(self, t0: float, t1: float) -> int:
        with self.lock:
            return sum(1 for a, _ in self.times if t0 <= a <= t1)


class Ticker:
    """Calls `tick(n)` every `period` s on a thread until stopped (at most `limit_s`);
    `sent` keeps (n, stamp_ns) of each tick that returned the stamp it published."""

    def __init__(self, period: float, tick: Callable[[int], int], limit_s: float = 300.0):
        self._stop = threading.Event()
        self._period, self._tick, self._limit = period, tick, limit_s
        self.sent: list[tuple[int, int]] = []  # (n, stamp_ns)
        self._thread = threading.Thread(target=self._run, name="ticker", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        end = time.monotonic() + self._limit
        n = 0
        while not self._stop.wait(self._period) and time.monotonic() < end:
            n += 1
            with contextlib.suppress(Exception):  # a put during a cut is dropped, not fatal
                self.sent.append((n, self._tick(n)))

    def longest_gap(self, t0_ns: int, t1_ns: int) -> float:
        """Longest time (s) without a send stamped in [t0_ns, t1_ns] (the ends count)."""
        return longest_gap([float(s) for _, s in list(self.sent)], t0_ns, t1_ns) / 1e9

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10)


def wait_out(until: float) -> None:
    """Let a fault last until the monotonic time `until` (the fault's duration is the
    experiment, not a synchronisation: nothing to wait for instead)."""
    threading.Event().wait(max(0.0, until - time.monotonic()))


@dataclass
class Bed:
    """A TLS + ACL router reachable from one namespace, and a loopback side for the
    robot computer's own sessions."""

    profile: HostProfile
    remote_endpoint: str  # what the namespaced host dials
    local_endpoint: str


def start_router(started: Callable[..., Process], tmp_path: Path, host_addr: str) -> Bed:
    certs = tmp_path / "certs"
    done = make_certs(certs, host_addr)
    assert done.returncode == 0, done.stderr
    work = tmp_path / "zenoh"
    work.mkdir()
    profile = HostProfile(certs, work)
    remote = f"tls/{host_addr}:{free_port()}"
    local_port = free_port()
    local = f"tls/{LOOPBACK}:{local_port}"
    started(buddybot_argv("router", "--listen", remote, "--listen", local,
                          "--zenoh-config", profile.zenoh_file("router")), "router")
    wait_port(local_port, timeout=30)
    return Bed(profile, remote, local)


def start_eye_screen(started: Callable[..., Process], bed: Bed,
                     exec_argv: Callable[..., list[str]], tmp_path: Path) -> PageProbe:
    """The real eye renderer in the namespace (no browser) and a page probe there."""
    port = free_port()  # inside the namespace any port is free; this one is just unique
    config = bed.profile.toml("eye-screen", bed.remote_endpoint)
    started(exec_argv(*buddybot_argv("run", "eye-renderer", "--no-browser", "--host", LOOPBACK,
                                     "--port", str(port), "--config", str(config))),
            "eye-renderer")
    probe = started(exec_argv(sys.executable, "-c", PAGE_PROBE,
                              f"ws://{LOOPBACK}:{port}/ws?eye=both", "400"), "page")
    return PageProbe(probe)


@dataclass
class TokenTimes:
    """When node `name`'s liveliness token went away at a watcher (the router dropped
    the session: how long a dead link takes to be noticed) and came back (a new
    session is up)."""

    gone: float | None = None
    back: float | None = None
    _up: bool = False


def token_times(watcher: Node, name: str) -> TokenTimes:
    times = TokenTimes()

    def on_change(instances: frozenset[str]) -> None:
        if instances and not times._up:
            times._up = True
            if times.gone is not None and times.back is None:
                times.back = time.monotonic()
        elif not instances and times._up:
            times._up = False
            if times.gone is None:
                times.gone = time.monotonic()

    watcher.watch_node(name, on_change)
    return times


def token_gone_at(watcher: Node, name: str) -> Callable[[], float | None]:
    times = token_times(watcher, name)
    return lambda: times.gone


# --- a cut link ---------------------------------------------------------------------------


@pytest.fixture
def eye_ns() -> Iterator[Namespace]:
    with veth_namespace("bbey") as ns:
        yield ns


@pytest.fixture
def camera_ns() -> Iterator[Namespace]:
    with veth_namespace("bbcm") as ns:
        yield ns


@pytest.mark.integration
def test_eye_screen_shows_the_newest_state_within_a_second_of_a_cut_link_coming_back(
    eye_ns: Namespace, started: Callable[..., Process], tmp_path: Path
) -> None:
    """The cable pulled at the eye screen (the interface goes down: no carrier)."""
    eye_screen_cut(started, tmp_path, eye_ns.host_addr, eye_ns.exec_argv, eye_ns.set_link,
                   "ip link set down", RECOVERY_S)


def eye_screen_cut(started: Callable[..., Process], tmp_path: Path, host_addr: str,
                   exec_argv: Callable[..., list[str]], set_link: Callable[[bool], None],
                   how: str, budget_s: float) -> None:
    """Latched eye state set while the screen is cut off reaches its page within
    `budget_s` of the link coming back; the robot's own readers never stall."""
    bed = start_router(started, tmp_path, host_addr)
    robot = Node("eyes", connect=[bed.local_endpoint],
                 zenoh_config_file=bed.profile.zenoh_file("robot"))
    watcher = Node("watcher", connect=[bed.local_endpoint],
                   zenoh_config_file=bed.profile.zenoh_file("operator"))
    gaze_ticker: Ticker | None = None
    try:
        expression = robot.publisher(keys.EXPRESSION)
        lids = robot.publisher(keys.LIDS)
        gaze = robot.publisher(keys.EYES_DIRECTION)
        expression.put(m.ScreenExpression(stamp_ns=m.now_ns(), action=1))
        lids.put(m.EyeLidControl(stamp_ns=m.now_ns(), eye_id=2, top_lid_position=10,
                                 bottom_lid_position=10))
        def look(n: int) -> int:
            stamp = m.now_ns()
            gaze.put(m.EyesDirection(stamp_ns=stamp, yaw=float(n % 30), pitch=0.0))
            return stamp

        gaze_ticker = Ticker(GAZE_PERIOD_S, look)
        gone = token_gone_at(watcher, "eye-renderer")
        local_gaze = Arrivals()  # a reader on the robot computer, next to the router
        watcher.subscribe(keys.EYES_DIRECTION, local_gaze.on)
        page = start_eye_screen(started, bed, exec_argv, tmp_path)
        page.first("expression", lambda x: x["action"] == 1, timeout=90)
        page.first("lids", lambda x: x["top_lid_position"] == 10, timeout=30)
        page.first("direction", lambda x: True, timeout=30)

        set_link(False)
        t_cut, t_cut_ns = time.monotonic(), m.now_ns()
        # The robot changes its mind while the screen is away: this is what the screen
        # must show once it is back (latched state, not the stream).
        expression.put(m.ScreenExpression(stamp_ns=m.now_ns(), action=4))
        lids.put(m.EyeLidControl(stamp_ns=m.now_ns(), eye_id=2, top_lid_position=70,
                                 bottom_lid_position=20))
        wait_out(t_cut + CUT_S)
        noticed = gone()
        # The link is back at some moment inside set_link, which a busy machine can take
        # a few hundred ms to return from: what arrives before t_plug crossed a cut
        # link; the recovery is timed from t_up, when the link is surely back.
        t_plug = time.monotonic()
        set_link(True)
        t_up, t_up_ns = time.monotonic(), m.now_ns()

        new_expression = page.first("expression", lambda x: x["action"] == 4, after=t_plug,
                                    timeout=60)
        new_lids = page.first("lids", lambda x: x["top_lid_position"] == 70, after=t_plug,
                              timeout=60)
        new_gaze = page.first("direction", lambda x: True, after=t_plug, timeout=60)
        during = [e for e in page.events() if e.topic == "direction"
                  and t_cut + 0.5 < e.t < t_plug]
        state_s = max(new_expression.t, new_lids.t) - t_up
        local_gap = local_gaze.longest_gap(t_cut, t_up)
        local_delay = local_gaze.longest_delay(t_cut, t_up)
        sent_gap = gaze_ticker.longest_gap(t_cut_ns, t_up_ns)
        print(f"\neye screen, {CUT_S:.0f} s cut ({how}): dead link noticed by the router after "
              f"{'never' if noticed is None else f'{noticed - t_cut:.2f} s'}; after the link "
              f"was put back ({t_up - t_plug:.3f} s to return): expression "
              f"{new_expression.t - t_plug:.3f} s, lids {new_lids.t - t_plug:.3f} s, gaze "
              f"{new_gaze.t - t_plug:.3f} s; longest gaze gap "
              f"on the robot computer during the cut {local_gap:.2f} s (sent: {sent_gap:.2f} s), "
              f"longest delay {local_delay:.3f} s")
        assert not during, f"{len(during)} gaze messages crossed a cut link: the cut was not real"
        assert noticed is not None and noticed - t_cut < LEASE_MS / 1000 + 2.0, \
            "the router should drop a silent eye screen after about one lease"
        # Held back: late, or missing where the sender sent (a busy machine may
        # starve the sender itself; that is no gap of the router's).
        assert local_delay < 1.0, "a cut eye screen held back the gaze of the robot's own readers"
        assert local_gap < sent_gap + 1.0, "the robot's own readers missed gaze during the cut"
        assert state_s <= budget_s, f"state right only {state_s:.2f} s after the link came back"
    finally:
        if gaze_ticker is not None:
            gaze_ticker.stop()
        watcher.close()
        robot.close()


@pytest.mark.integration
def test_camera_host_images_and_faces_flow_within_a_second_of_a_cut_link_coming_back(
    camera_ns: Namespace, started: Callable[..., Process], tmp_path: Path
) -> None:
    camera_host_cut(started, tmp_path, camera_ns.host_addr, camera_ns.exec_argv,
                    camera_ns.set_link, "ip link set down", RECOVERY_S)


def camera_host_cut(started: Callable[..., Process], tmp_path: Path, host_addr: str,
                    exec_argv: Callable[..., list[str]], set_link: Callable[[bool], None],
                    how: str, budget_s: float) -> None:
    """Real camera (--sim) and face detector on the camera host: the camera's session
    is back (its token seen by the robot computer) and new images and faces reach the
    robot computer within `budget_s` of the link coming back."""
    bed = start_router(started, tmp_path, host_addr)
    robot = Node("controller", connect=[bed.local_endpoint],
                 zenoh_config_file=bed.profile.zenoh_file("robot"))
    try:
        images, faces = Arrivals(), Arrivals()
        robot.subscribe(keys.CAMERA_IMAGE, images.on, camera="front")
        robot.subscribe(keys.FACE, faces.on, camera="front")
        camera_token = token_times(robot, "camera")
        config = bed.profile.toml("camera-host", bed.remote_endpoint)
        started(exec_argv(*buddybot_argv(
            "run", "camera", "--sim", "--fps", "10", "--encoding", "jpeg",
            "--config", str(config))), "camera")
        started(exec_argv(*buddybot_argv(
            "run", "face-detector", "--config", str(config))), "face-detector")
        # Images first: a failure then says which side never started.
        retry_until(lambda: images.first_after(0.0), 180, 0.2, what="images from the camera host")
        retry_until(lambda: faces.first_after(0.0), 180, 0.2, what="faces from the camera host")

        set_link(False)
        t_cut = time.monotonic()
        wait_out(t_cut + CUT_S)
        noticed = camera_token.gone
        t_plug, plug_ns = time.monotonic(), m.now_ns()  # as in eye_screen_cut
        set_link(True)
        t_up = time.monotonic()

        image_at = retry_until(lambda: images.first_after(t_plug, plug_ns), 60, 0.02,
                               what="a new image after the link came back")
        face_at = retry_until(lambda: faces.first_after(t_plug, plug_ns), 60, 0.02,
                              what="a new face after the link came back")
        session_at = retry_until(lambda: camera_token.back, 60, 0.02,
                                 what="the camera's session back")
        during = images.between(t_cut + 0.5, t_plug)
        print(f"\ncamera host, {CUT_S:.0f} s cut ({how}): dead link noticed by the router after "
              f"{'never' if noticed is None else f'{noticed - t_cut:.2f} s'}; after the link "
              f"was put back ({t_up - t_plug:.3f} s to return): camera session "
              f"{session_at - t_plug:.3f} s, first new image {image_at - t_plug:.3f} s, "
              f"first new face {face_at - t_plug:.3f} s")
        assert during == 0, f"{during} images crossed a cut link: the cut was not real"
        assert noticed is not None and noticed - t_cut < LEASE_MS / 1000 + 2.0
        assert session_at - t_up <= budget_s, "the camera host took too long to reconnect"
        assert image_at - t_up <= budget_s
        assert face_at - t_up <= budget_s
    finally:
        robot.close()


# --- a slow, lossy link ------------------------------------------------------------------


TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000


def _open_tap(name: str) -> int:
    fd = os.open("/dev/net/tun", os.O_RDWR)
    try:
        fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TAP | IFF_NO_PI))
    except OSError:
        os.close(fd)
        raise
    return fd


class LinkEmulator:
    """A cable with a delay and random loss, in user space.

    Two TAP devices (one here, one moved into the namespace) and a thread that copies
    Ethernet frames between them, holding each for `delay_s` and dropping each with
    probability `loss`, both ways, like `tc qdisc add ... netem delay D loss L` on
    both ends. TCP, TLS and Zenoh run unchanged over it."""

    def __init__(self, host_fd: int, ns_fd: int, seed: int = 11) -> None:
        self.delay_s = 0.0
        self.loss = 0.0
        self.forwarded = 0
        self.dropped = 0
        self._other = {host_fd: ns_fd, ns_fd: host_fd}
        self._rng = random.Random(seed)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="link-emulator", daemon=True)
        self._thread.start()

    def _run(self, limit_s: float = 900.0) -> None:
        end = time.monotonic() + limit_s
        queue: list[tuple[float, int, int, bytes]] = []  # (due, order, out fd, frame)
        order = 0
        while not self._stop.is_set() and time.monotonic() < end:
            wait = 0.01 if not queue else min(0.01, max(0.0, queue[0][0] - time.monotonic()))
            readable, _, _ = select.select(list(self._other), [], [], wait)
            for fd in readable:
                try:
                    frame = os.read(fd, 65536)
                except OSError:
                    continue
                if self._rng.random() < self.loss:
                    self.dropped += 1
                    continue
                order += 1
                heapq.heappush(queue, (time.monotonic() + self.delay_s, order,
                                       self._other[fd], frame))
            now = time.monotonic()
            while queue and queue[0][0] <= now:
                _, _, out, frame = heapq.heappop(queue)
                with contextlib.suppress(OSError):  # device going away at the end
                    os.write(out, frame)
                    self.forwarded += 1

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10)


@dataclass
class TapHost:
    ns: str
    host_addr: str
    ns_addr: str
    link: LinkEmulator

    def exec_argv(self, *argv: str) -> list[str]:
        return ["ip", "netns", "exec", self.ns, *argv]


@contextlib.contextmanager
def tap_namespace(prefix: str) -> Iterator[TapHost]:
    """A namespace joined to this one through a `LinkEmulator`; all removed after."""
    skip_without_namespaces()
    if not os.path.exists("/dev/net/tun"):
        pytest.skip("needs /dev/net/tun for the link emulator")
    tag = f"{os.getpid() % 10000}{random.randrange(100):02d}"
    name, tap_host, tap_ns = f"{prefix}{tag}", f"bbth{tag}", f"bbtn{tag}"
    subnet = f"10.{random.randrange(200, 250)}.{random.randrange(256)}"
    made = ip("netns", "add", name)
    if made.returncode != 0:
        pytest.skip(f"cannot make a network namespace: {made.stderr.strip()}")
    fds: list[int] = []
    link: LinkEmulator | None = None
    try:
        try:
            fds = [_open_tap(tap_host), _open_tap(tap_ns)]
        except OSError as exc:
            pytest.skip(f"cannot make a TAP device: {exc}")
        steps = [
            ("link", "set", tap_ns, "netns", name),
            ("addr", "add", f"{subnet}.1/30", "dev", tap_host),
            ("link", "set", tap_host, "up"),
            ("-n", name, "addr", "add", f"{subnet}.2/30", "dev", tap_ns),
            ("-n", name, "link", "set", tap_ns, "up"),
            ("-n", name, "link", "set", "lo", "up"),
        ]
        for step in steps:
            done = ip(*step)
            assert done.returncode == 0, f"ip {' '.join(step)}: {done.stderr}"
        link = LinkEmulator(fds[0], fds[1])
        yield TapHost(name, f"{subnet}.1", f"{subnet}.2", link)
    finally:
        if link is not None:
            link.stop()
        for fd in fds:
            os.close(fd)  # a TAP device without its file goes away with it
        ip("netns", "del", name)


DIAL_PROBE = """
import sys, time, zenoh
from buddybot.runtime.node import zenoh_config
c = zenoh_config(connect=[sys.argv[1]], base_file=sys.argv[2])
c.insert_json5("connect/timeout_ms", "30000")
t0 = time.monotonic()
zenoh.open(c).close()
print("OPENED", time.monotonic() - t0)
"""


def dial(exec_argv: Callable[..., list[str]], endpoint: str, zenoh_file: str) -> float:
    """Seconds a fresh client session in the namespace takes to open (fails the test
    if it cannot within 30 s: a connection attempt timeout too short for the link)."""
    done = subprocess.run(exec_argv(sys.executable, "-c", DIAL_PROBE, endpoint, zenoh_file),
                          capture_output=True, text=True, timeout=90, check=False)
    opened = [ln for ln in done.stdout.splitlines() if ln.startswith("OPENED ")]
    assert opened, f"no session over the link: {done.stdout[-500:]} {done.stderr[-1500:]}"
    return float(opened[0].split()[1])


@pytest.fixture
def slow_eye_host() -> Iterator[TapHost]:
    with tap_namespace("bbsl") as host:
        yield host


@pytest.mark.integration
def test_gaze_keeps_flowing_over_a_slow_lossy_link(
    slow_eye_host: TapHost, started: Callable[..., Process], tmp_path: Path
) -> None:
    """100 ms delay and 5 % loss each way (200 ms round trip): most gaze messages
    still reach the eye page, without long stalls, and a new session still opens over
    such a link (the clients' 1.5 s connection-attempt limit leaves room for it)."""
    host = slow_eye_host
    bed = start_router(started, tmp_path, host.host_addr)
    robot = Node("eyes", connect=[bed.local_endpoint],
                 zenoh_config_file=bed.profile.zenoh_file("robot"))
    ticker: Ticker | None = None
    try:
        gaze = robot.publisher(keys.EYES_DIRECTION)
        robot.publisher(keys.EXPRESSION).put(m.ScreenExpression(stamp_ns=m.now_ns(), action=1))

        def tick(n: int) -> int:
            stamp = m.now_ns()
            gaze.put(m.EyesDirection(stamp_ns=stamp, yaw=float(n % 30), pitch=0.0))
            return stamp

        ticker = Ticker(GAZE_PERIOD_S, tick)
        page = start_eye_screen(started, bed, host.exec_argv, tmp_path)
        page.first("expression", lambda x: x["action"] == 1, timeout=90)
        page.first("direction", lambda x: True, timeout=30)

        host.link.delay_s, host.link.loss = 0.1, 0.05
        t0 = time.monotonic()
        wait_out(t0 + 2.0)  # let the link settle into its new behaviour
        window_start_ns = m.now_ns()
        t1 = time.monotonic()
        wait_out(t1 + 8.0)
        window_end_ns = m.now_ns()
        wait_out(time.monotonic() + 2.0)  # the last ones are still on the slow cable
        sent = [s for _, s in ticker.sent if window_start_ns <= s <= window_end_ns]
        got = [e for e in page.events() if e.topic == "direction"
               and window_start_ns <= int(e.msg["stamp_ns"]) <= window_end_ns]
        latency_ms = sorted((e.wall_ns - int(e.msg["stamp_ns"])) / 1e6 for e in got)
        arrivals = sorted(e.t for e in got)
        gaps = [b - a for a, b in itertools.pairwise(arrivals)]
        fraction = len(got) / max(1, len(sent))
        print(f"\ngaze over 100 ms delay + 5 % loss each way: {len(got)} of {len(sent)} "
              f"({fraction:.0%}) reached the page in 8 s; latency median "
              f"{statistics.median(latency_ms) if latency_ms else float('nan'):.0f} ms, p95 "
              f"{latency_ms[int(0.95 * (len(latency_ms) - 1))] if latency_ms else float('nan'):.0f}"
              f" ms; longest gap {max(gaps, default=float('nan')):.2f} s; emulator forwarded "
              f"{host.link.forwarded} frames, dropped {host.link.dropped}")
        dial_s = [dial(host.exec_argv, bed.remote_endpoint,
                       bed.profile.zenoh_file("eye-screen")) for _ in range(3)]
        print(f"new eye-screen sessions over the same link opened in "
              f"{', '.join(f'{d:.2f}' for d in dial_s)} s")
        assert host.link.dropped > 0, "the emulator dropped nothing: the loss was not applied"
        assert latency_ms and latency_ms[0] >= 90, "the delay was not applied"
        assert fraction >= 0.5, f"only {fraction:.0%} of the gaze arrived"
        assert max(gaps, default=99.0) < 2.0, "the gaze stalled"
    finally:
        if ticker is not None:
            ticker.stop()
        robot.close()


@pytest.mark.integration
def test_eye_screen_recovers_from_a_silent_black_hole(
    slow_eye_host: TapHost, started: Callable[..., Process], tmp_path: Path
) -> None:
    """The harder cut: the link stays "up" but every frame is lost (netem loss 100 %,
    a Wi-Fi that went deaf), so nothing tells either side; only the lease does."""
    host = slow_eye_host

    def set_link(up: bool) -> None:
        host.link.loss = 0.0 if up else 1.0

    eye_screen_cut(started, tmp_path, host.host_addr, host.exec_argv, set_link, "loss 100 %",
                   SILENT_RECOVERY_S)


@pytest.fixture
def slow_camera_host() -> Iterator[TapHost]:
    with tap_namespace("bbsc") as host:
        yield host


@pytest.mark.integration
def test_camera_host_recovers_from_a_silent_black_hole(
    slow_camera_host: TapHost, started: Callable[..., Process], tmp_path: Path
) -> None:
    """The camera host behind a link that silently loses everything for 10 s: this is
    the case the clients' `open_timeout` is for (with Zenoh's 10 s default, recovery
    took ~3 s, an attempt stuck in TCP's SYN back-off)."""
    host = slow_camera_host

    def set_link(up: bool) -> None:
        host.link.loss = 0.0 if up else 1.0

    # + 3 s: in about one full run of three, the router accepts the camera's new session
    # within ~1 s (its debug log) but the robot computer sees the camera's token and
    # frames only ~2 s after that; never seen for the eye screen or a pulled cable, and
    # not yet explained (docs/deploy.md, "Network faults").
    camera_host_cut(started, tmp_path, host.host_addr, host.exec_argv, set_link, "loss 100 %",
                    SILENT_RECOVERY_S + 3.0)
