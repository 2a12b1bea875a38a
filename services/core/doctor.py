"""`buddybot doctor`: is this robot healthy, and if not, what exactly is wrong?

Each check is a small function returning a `Check` (name, OK/WARN/FAIL,
one line of detail), so the verdicts are tested on crafted inputs without a
robot. Two families:

* quick checks need no running robot (config, devices, versions, the router
  port): `buddybot up` runs them at start and prints their summary;
* bus checks ask a running robot (router, live nodes, sensor rates, the eye
  page, clocks), each bounded by a timeout so `doctor` never hangs on a dead
  or silent bus.

Pure where it can be: the functions that judge (`judge_rate`, `judge_nodes`,
`judge_clock`...) take numbers and lists; the ones that look (`probe_bus`,
`open_camera`...) are thin and kept apart.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import platform
import socket
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

from buddybot.core.config import DEFAULT_ENDPOINT, ConfigBase

Level = Literal["OK", "WARN", "FAIL"]
OK: Level = "OK"
WARN: Level = "WARN"
FAIL: Level = "FAIL"

CLOCK_MIN_EPOCH_S = 1_704_067_200.0
"""2024-01-01T00:00:00Z: a system clock before this was never set (no RTC, no NTP)."""
CLOCK_SKEW_WARN_S = 2.0
"""A received stamp further than this from our clock: two hosts disagree on the time."""
RADAR_HZ = 10.0
"""An LD2410 reports about 10 times a second (the simulator too)."""
CAMERA_DEFAULT_FPS = 30.0
"""The camera's pace when `[camera] fps` is not set (the simulation's, most webcams')."""
RATE_WARN_FRACTION = 0.5
"""A stream below this fraction of its expected rate is a warning."""
VERSION_PACKAGES = (
    ("buddybot", ("buddybot",)),
    ("zenoh", ("eclipse-zenoh",)),
    ("msgspec", ("msgspec",)),
    ("numpy", ("numpy",)),
    ("opencv", ("opencv-python-headless", "opencv-python", "opencv-contrib-python")),
    ("ai-edge-litert", ("ai-edge-litert",)),
)
"""(shown name, distribution names to try): what a bug report needs to name."""


@dataclass(frozen=True)
class Check:
    """One verdict: `name` says what was checked, `detail` what was found."""

    name: str
    level: Level
    detail: str

    @property
    def failed(self) -> bool:
        return self.level == FAIL


# --- report -------------------------------------------------------------------------


def format_report(checks: Sequence[Check]) -> str:
    """One line per check, aligned, then the summary line."""
    width = max((len(c.name) for c in checks), default=0)
    lines = [f"{c.level:<4}  {c.name:<{width}}  {c.detail}" for c in checks]
    lines.append(summary(checks))
    return "\n".join(lines)


def summary(checks: Sequence[Check]) -> str:
    """One line: counts, and the names of what is not OK (`up` prints this)."""
    counts = {level: sum(c.level == level for c in checks) for level in (OK, WARN, FAIL)}
    text = f"doctor: {counts[OK]} ok, {counts[WARN]} warn, {counts[FAIL]} fail"
    bad = [f"{c.name} ({c.level})" for c in checks if c.level != OK]
    return text + (f": {', '.join(bad)}" if bad else "")


def to_json(checks: Sequence[Check]) -> str:
    return json.dumps({"ok": not any(c.failed for c in checks),
                       "checks": [asdict(c) for c in checks]}, indent=2)


def exit_code(checks: Sequence[Check]) -> int:
    """1 when any check failed, else 0 (warnings are not failures)."""
    return 1 if any(c.failed for c in checks) else 0


# --- judging (pure) -----------------------------------------------------------------


def judge_config(config: ConfigBase | None, error: str | None) -> Check:
    if config is None:
        return Check("config", FAIL, error or "not loaded")
    return Check("config", OK, config.source or "defaults (no config file)")


def judge_port(endpoint: str, accepting: bool, nodes: list[str] | None) -> Check:
    """The router port before `up`: free, our kind of router, or a stranger.

    `nodes` is what a Zenoh probe found there (None: no Zenoh router answered).
    """
    name = "router port"
    if not accepting:
        return Check(name, OK, f"{endpoint} is free")
    if nodes is None:
        return Check(name, FAIL, f"{endpoint} is taken by something that is not a Zenoh "
                     "router")
    who = f"live nodes: {', '.join(nodes)}" if nodes else "no live BuddyBot nodes"
    return Check(name, OK, f"{endpoint}: a Zenoh router runs there ({who})")


def judge_router(endpoint: str, reachable: bool, error: str = "") -> Check:
    transport = endpoint.partition("/")[0] or "?"
    if reachable:
        return Check("router", OK, f"reachable at {endpoint} (transport {transport})")
    why = error.split(". Retry")[0] if error else "nothing answers"
    why = why.removeprefix(f"no Zenoh router at {endpoint}: ")  # we say where already
    return Check("router", FAIL, f"{endpoint} (transport {transport}): {why}")


def judge_nodes(expected: Iterable[str], live: dict[str, set[str]]) -> Check:
    """Every expected node alive, exactly once."""
    expected = list(expected)
    missing = [n for n in expected if n not in live]
    dupes = sorted(n for n, ids in live.items() if len(ids) > 1)
    extra = sorted(n for n in live if n not in expected)
    alive = f"{len(expected) - len(missing)}/{len(expected)} alive"
    if missing:
        return Check("nodes", FAIL, f"{alive}; missing: {', '.join(missing)}")
    if dupes:
        return Check("nodes", WARN, f"{alive}; more than one instance of: {', '.join(dupes)}")
    return Check("nodes", OK, alive + (f" (also: {', '.join(extra)})" if extra else ""))


def judge_rate(name: str, count: int, window_s: float, expected_hz: float) -> Check:
    """A stream's measured rate against what it should be."""
    hz = count / window_s if window_s > 0 else 0.0
    text = f"{hz:.1f} Hz over {window_s:.1f} s (expected ~{expected_hz:g} Hz)"
    if count == 0:
        return Check(name, FAIL, f"nothing received in {window_s:.1f} s "
                     f"(expected ~{expected_hz:g} Hz)")
    if hz < expected_hz * RATE_WARN_FRACTION:
        return Check(name, WARN, text)
    return Check(name, OK, text)


def judge_clock(wall_s: float, mono_before: float, mono_after: float,
                stamp_ns: int | None = None) -> Check:
    """Wall clock set (after 2024), monotonic clock not going back, and, if a message
    was received, its stamp near our time (the sender's clock agrees with ours)."""
    if wall_s < CLOCK_MIN_EPOCH_S:
        return Check("clock", FAIL, f"system time {time.strftime('%Y-%m-%d', time.gmtime(wall_s))}"
                     " is before 2024: set the clock (NTP, RTC)")
    if mono_after < mono_before:
        return Check("clock", FAIL, "the monotonic clock went backwards")
    if stamp_ns is not None:
        skew = wall_s - stamp_ns / 1e9
        if abs(skew) > CLOCK_SKEW_WARN_S:
            return Check("clock", WARN, f"a received message is stamped {skew:+.1f} s from "
                         "our clock: the hosts disagree on the time (NTP?)")
        return Check("clock", OK, f"set; a received stamp is {skew * 1000:+.0f} ms from ours")
    return Check("clock", OK, "set (after 2024), monotonic")


def judge_versions(found: dict[str, str | None]) -> Check:
    """Versions of what BuddyBot runs on; a missing one is a warning (its service
    cannot start, the others can)."""
    text = ", ".join(f"{k} {v or 'MISSING'}" for k, v in found.items())
    missing = [k for k, v in found.items() if v is None]
    return Check("versions", WARN if missing else OK, text)


# --- looking (thin) -----------------------------------------------------------------


def versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {"python": platform.python_version()}
    for shown, dists in VERSION_PACKAGES:
        out[shown] = None
        for dist in dists:
            try:
                out[shown] = importlib.metadata.version(dist)
                break
            except importlib.metadata.PackageNotFoundError:
                continue
    return out


def host_port(endpoint: str) -> tuple[str, int]:
    """(host, port) of a Zenoh endpoint `proto/host:port`; ValueError if it has none."""
    _, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    host = host.strip("[]")
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    return host, int(port.split("#")[0])


def accepting(endpoint: str, timeout: float = 0.5) -> bool:
    """Whether something accepts TCP connections on `endpoint` (tcp or tls) right now."""
    try:
        with socket.create_connection(host_port(endpoint), timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


def check_serial(sensors: Sequence[str], sim: bool) -> list[Check]:
    """Each configured radar's serial port present and usable."""
    if sim or not sensors:
        return [Check("radar serial", OK, "simulated (no serial port needed)")]
    checks = []
    for i, url in enumerate(sensors):
        name = f"radar serial {i}"
        if "://" in url:
            checks.append(Check(name, OK, f"{url}: network serial, not opened here"))
        elif not os.path.exists(url):
            checks.append(Check(name, FAIL, f"{url} does not exist (unplugged? wrong name?)"))
        elif not os.access(url, os.R_OK | os.W_OK):
            checks.append(Check(name, FAIL, f"{url}: no read/write permission "
                                "(add the user to the dialout group)"))
        else:
            checks.append(Check(name, OK, f"{url} present"))
    return checks


def check_camera(source: str, sim: bool, in_use: bool = False,
                 opener: Callable[[str], bool] | None = None) -> Check:
    """The configured camera device opens (a file exists). Not in sim; not while the
    camera service holds it (`in_use`)."""
    if sim or not source:
        return Check("camera device", OK, "simulated (no camera needed)")
    if in_use:
        return Check("camera device", OK, f"{source}: held by the running camera service")
    if "://" in source:
        return Check("camera device", OK, f"{source}: network stream, not opened here")
    if not source.isdigit() and not source.startswith("/dev/") and "%" not in source:
        if os.path.exists(source):
            return Check("camera device", OK, f"{source}: file present")
        return Check("camera device", FAIL, f"{source} does not exist")
    opened = (opener or open_camera)(source)
    if opened:
        return Check("camera device", OK, f"{source} opens")
    return Check("camera device", FAIL, f"{source} cannot be opened (unplugged, or in use "
                 "by another program?)")


def open_camera(source: str) -> bool:
    """Open and release an OpenCV capture of `source` (an index or a device path)."""
    try:
        import cv2
    except ImportError:
        return False
    cap = cv2.VideoCapture(int(source) if source.isdigit() else source)
    try:
        return bool(cap.isOpened())
    finally:
        cap.release()


def check_audio(settings: Any, sim: bool, in_use: bool = False) -> Check:
    """The audio player's backend opens a device ("null" is fine in sim)."""
    backend = str(getattr(settings, "backend", "auto"))
    if backend == "null":
        return Check("audio device", OK if sim else WARN,
                     "null backend: the robot plays silently")
    if in_use:
        return Check("audio device", OK, f"{backend}: held by the running audio-player")
    try:
        from buddybot.core import registry

        entry = registry.service("audio-player")
        assert entry is not None
        opened = entry.device_opener()(settings)
    except Exception as exc:  # AudioError, miniaudio errors: the message says why
        return Check("audio device", OK if sim else FAIL, f"{backend}: {exc}")
    try:
        if opened.warning:
            return Check("audio device", OK if sim else WARN, opened.warning)
        return Check("audio device", OK, f"{backend}: opened ({opened.backend})")
    finally:
        opened.device.close()


def check_display(host: str, port: int, timeout: float) -> Check:
    """The eye renderer's page server answers `/healthz`."""
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    url = f"http://{host}:{port}/healthz"
    try:
        with urllib.request.urlopen(url, timeout=timeout) as reply:
            return Check("displays", OK, f"eye page server answers at {url} "
                         f"(HTTP {reply.status})")
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        return Check("displays", FAIL, f"eye page server does not answer at {url}: {reason}")


# --- the bus ------------------------------------------------------------------------


@dataclass
class BusReport:
    """What one bounded look at the bus found (filled by `probe_bus`)."""

    endpoint: str
    reachable: bool = False
    error: str = ""
    live: dict[str, set[str]] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    """Samples per stream name over `window_s`."""
    window_s: float = 0.0
    last_stamp_ns: int | None = None


def probe_bus(endpoint: str, robot: str, zenoh_file: str | None, timeout: float,
              window_s: float, streams: dict[str, str], *, all_robots: bool = False,
              stop: threading.Event | None = None) -> BusReport:
    """Open a probe on `endpoint` (giving up after `timeout`), list the live nodes (of
    every robot, as `robot/name`, with `all_robots`) and count the samples of
    `streams` (name -> absolute key) for `window_s` seconds."""
    from buddybot.core import keys
    from buddybot.core import messages as m
    from buddybot.core.node import Node, zenoh_config

    report = BusReport(endpoint)
    try:
        config = zenoh_config(connect=[endpoint], base_file=zenoh_file)
        config.insert_json5("connect/timeout_ms", str(max(1, int(timeout * 1000))))
        node = Node("doctor", robot=robot, connect=[endpoint], config=config, probe=True,
                    stop_event=stop)
    except KeyboardInterrupt:
        report.error = "interrupted"
        return report
    except Exception as exc:  # ConnectionError: no router, or it refused us (TLS)
        report.error = str(exc)
        return report
    lock = threading.Lock()
    with node:
        report.reachable = True
        report.live = node.node_instances(all_robots=all_robots, timeout=timeout)
        counts = dict.fromkeys(streams, 0)

        def counter(name: str) -> Callable[[str, bytes, str], None]:
            def on_sample(_key: str, _payload: bytes, _encoding: str) -> None:
                with lock:
                    counts[name] += 1
            return on_sample

        def on_diagnostics(_key: str, payload: bytes, _encoding: str) -> None:
            try:
                msg = keys.DIAGNOSTICS.codec.decode(payload, m.DiagnosticStatus)
            except Exception:
                return
            stamp = getattr(msg, "stamp_ns", None)
            if isinstance(stamp, int):
                with lock:
                    report.last_stamp_ns = stamp

        subs = [node.subscribe_raw(key, counter(name)) for name, key in streams.items()]
        subs.append(node.subscribe_raw(node.key(keys.DIAGNOSTICS), on_diagnostics))
        start = time.monotonic()
        node.stop_event.wait(window_s)
        with lock:
            report.window_s = time.monotonic() - start
            report.counts = dict(counts)
        for sub in subs:
            sub.close()
    return report


# --- the two families ---------------------------------------------------------------


@dataclass
class Options:
    """What the checks need to know besides the config."""

    sim: bool = False
    endpoint: str = DEFAULT_ENDPOINT
    robot: str = "buddy"
    expected: list[str] = field(default_factory=list)
    timeout: float = 3.0
    window_s: float = 2.0
    zenoh_file: str | None = None
    stop: threading.Event | None = None
    """Set by Ctrl-C: a wait on the bus ends early."""


def quick_checks(config: ConfigBase | None, config_error: str | None, opts: Options,
                 *, port: bool = True, in_use: frozenset[str] = frozenset()) -> list[Check]:
    """Checks that need no running robot: config, devices, versions, router port.

    `in_use`: services running now (their devices are not opened again)."""
    checks = [judge_config(config, config_error)]
    if config is not None:
        sections = set(config.__struct_fields__)
        if "radar_bridge" in sections:
            sim = opts.sim or bool(getattr(config.radar_bridge, "sim", False))
            checks += check_serial(list(config.radar_bridge.sensors), sim)
        if "camera" in sections:
            cam = config.camera
            checks.append(check_camera(cam.source, opts.sim or bool(cam.sim),
                                       "camera" in in_use))
        if "audio_player" in sections:
            checks.append(check_audio(config.audio_player, opts.sim, "audio-player" in in_use))
    checks.append(judge_versions(versions()))
    if port:
        checks.append(port_check(opts.endpoint, opts.zenoh_file, opts.timeout, opts.robot))
    return checks


def port_check(endpoint: str, zenoh_file: str | None, timeout: float,
               robot: str = "buddy") -> Check:
    """Who holds the router's port: nobody, a Zenoh router (with whose nodes), or not
    a Zenoh router at all."""
    if not accepting(endpoint):
        return judge_port(endpoint, False, None)
    bus = probe_bus(endpoint, robot, zenoh_file, timeout, 0.0, {}, all_robots=True)
    return judge_port(endpoint, True, sorted(bus.live) if bus.reachable else None)


def bus_checks(config: ConfigBase, opts: Options) -> tuple[list[Check], frozenset[str]]:
    """Checks that ask the running robot, each bounded by `opts.timeout`; and the
    names of the live nodes (whose devices the quick checks must not open again)."""
    from buddybot.core import keys

    streams: dict[str, str] = {}
    prefix = keys.prefix(opts.robot)
    if "radar-bridge" in opts.expected:
        streams["radar frames"] = f"{prefix}/{keys.RADAR_FRAMES.wildcard()}"
    if "camera" in opts.expected:
        streams["camera images"] = f"{prefix}/{keys.CAMERA_IMAGE.wildcard()}"
    bus = probe_bus(opts.endpoint, opts.robot, opts.zenoh_file, opts.timeout,
                    opts.window_s if streams else 0.0, streams, stop=opts.stop)
    error = bus.error
    if not bus.reachable and opts.endpoint.startswith(("tcp/", "tls/")) \
            and not accepting(opts.endpoint):
        error = "nothing listens there (is the router or `buddybot up` running?)"
    checks = [judge_router(opts.endpoint, bus.reachable, error)]
    if not bus.reachable:
        return checks, frozenset()
    checks.append(judge_nodes(opts.expected, bus.live))
    if "radar frames" in streams:
        checks.append(judge_rate("radar frames", bus.counts["radar frames"], bus.window_s,
                                 RADAR_HZ))
    if "camera images" in streams:
        fps = float(getattr(config.camera, "fps", 0.0) or 0.0) if "camera" in set(
            config.__struct_fields__) else 0.0
        checks.append(judge_rate("camera images", bus.counts["camera images"], bus.window_s,
                                 fps or CAMERA_DEFAULT_FPS))
    if "eye-renderer" in opts.expected and "eye_renderer" in set(config.__struct_fields__):
        checks.append(check_display(config.eye_renderer.host, config.eye_renderer.port,
                                    opts.timeout))
    checks.append(clock_check(bus.last_stamp_ns))
    return checks, frozenset(bus.live)


def clock_check(stamp_ns: int | None = None) -> Check:
    before = time.monotonic()
    wall = time.time()
    return judge_clock(wall, before, time.monotonic(), stamp_ns)
