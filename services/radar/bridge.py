"""`buddybot run radar-bridge`: 1..N LD2410/LD2450 sensors on pyserial URLs -> the bus.

LD2410 reports go to `radar/<device>/frames`; LD2450 reports to
`radar/<device>/targets`, each target placed in the camera's frame by the
sensor's `[[radar_bridge.mount]]`. A sensor's model is recognised from its
first report frames at every connect (`models.py`), unless `models` names it.

A thin adapter: one reader thread per sensor
opens its URL (`/dev/ttyUSB0`, `socket://esp32.local:8881`,
`rfc2217://...`), feeds the bytes to the pure parser and publishes every
report frame at once, stamped with its arrival time. A sensor that
disappears is retried with exponential backoff while the others go on;
frames, bad frames, clamped energies and reconnects are counted in
`diagnostics/radar-bridge`.

At every connect the firmware version is asked for (0x00A0, inside
enable/end configuration): only V2.x firmware defines the last two bytes
of an engineering report as light level and OUT pin, so they are
published for V2.x only. A sensor that does not answer is read all the
same (fields empty). Any frame whose framing is intact (a report in an
unusual state such as background-noise detection, an ACK) shows the line
works: only a port with no intact frame at all is reopened.
"""

from __future__ import annotations

import argparse
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import msgspec
import serial

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar import ld2410, ld2450
from buddybot.radar.client import LD2410Client, RadarError
from buddybot.radar.convert import report_to_frame, report_to_targets
from buddybot.radar.ld2410 import ProtocolError, Report
from buddybot.radar.models import AUTO, MODELS, Frame, Sniffer, describe
from buddybot.radar.mounting import IDENTITY, Mount
from buddybot.radar.settings import RadarBridgeSettings
from buddybot.radar.urls import url_problem
from buddybot.radar.world_view import world_script
from buddybot.runtime.backoff import Backoff
from buddybot.runtime.errors import ConfigError, UsageError
from buddybot.runtime.limits import clip
from buddybot.runtime.node import Node, RateLimitedLog
from buddybot.runtime.overrides import given, merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext
from buddybot.sim.options import add_world_arguments, world_from

FIRMWARE_TIMEOUT_S = 0.5  # per ACK, two attempts: a mute sensor costs 1 s per connect
DRAIN_BYTES = 1 << 20
"""The most read from a port at once: everything that waits, in one go."""
FRESH_BYTES = 4096
"""The newest bytes of what waited that are parsed; older ones are a flood's backlog.
A sensor sends at most ~25 kB/s (256000 baud), 30-60 bytes per report at 10 Hz:
4 kB waiting means the reader fell behind by seconds (or a flood), so the older
reports are stale and dropped, counted, and only the newest reach the bus."""
NOISE_STATES = {
    ld2410.STATE_NOISE_DETECTING: "in progress",
    ld2410.STATE_NOISE_DETECTION_SUCCEEDED: "succeeded",
    ld2410.STATE_NOISE_DETECTION_FAILED: "failed",
}


@dataclass
class SensorStatus:
    url: str
    radar_id: int
    connected: bool = False
    frames: int = 0
    bad_frames: int = 0
    skipped_bytes: int = 0
    clamped: int = 0
    bad_out_pin: int = 0
    unusual_frames: int = 0
    reconnects: int = 0
    last_error: str = "connecting"
    ever_connected: bool = False
    last_frame: float = field(default=0.0)
    firmware: str = "unknown"
    # Whether this firmware's engineering reports end with light level and OUT pin.
    light_and_out: bool = False
    noise_detection: str = ""
    model: str = "unknown"  # as recognised from the frames: "LD2410 basic", "LD2450", ...
    model_changes: int = 0
    implausible_targets: int = 0
    stale_bytes: int = 0
    """Bytes of a backlog dropped unread (a flood, or the reader fell behind)."""
    superseded: int = 0
    """Reports of a backlog's newest bytes not published: a newer one was."""


class SensorReader:
    """Reads one sensor forever: open, parse, publish; on failure back off and reopen."""

    def __init__(self, url: str, radar_id: int, baudrate: int,
                 publish: Callable[[int, Frame, int], None], on_change: Callable[[], None],
                 stop: threading.Event, backoff: tuple[float, float], silence_s: float,
                 log: Any, query_firmware: bool = True, model: str = AUTO) -> None:
        self.status = SensorStatus(url, radar_id)
        self._model = model
        self._query_firmware = query_firmware
        self._baud = baudrate
        self._publish = publish
        self._on_change = on_change
        self._stop = stop
        self._backoff = Backoff(*backoff)  # (initial, maximum): this sensor's own series
        self._silence_s = silence_s
        self._log = log
        self.thread = threading.Thread(target=self._run, name=f"radar-{radar_id}", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                port = serial.serial_for_url(self.status.url, baudrate=self._baud, timeout=0.2)
            except (serial.SerialException, OSError, ValueError) as exc:
                self._failed(f"cannot open: {exc}")
                self._stop.wait(self._backoff.next())
                continue
            try:
                self._connected()
                self._read(port)
                self._backoff.reset()
            except (serial.SerialException, OSError) as exc:
                if self.status.frames:  # frames came: the link worked, start the series again
                    self._backoff.reset()
                self._failed(f"lost: {exc}")
            finally:
                try:
                    port.close()
                except Exception as exc:  # closing a dead port may fail too
                    self._log.debug("close %s: %s", clip(self.status.url), clip(str(exc)))
            self._stop.wait(self._backoff.delay)  # a lost link waits without growing the delay

    def _connected(self) -> None:
        st = self.status
        if st.ever_connected:
            st.reconnects += 1
        st.ever_connected = True
        st.connected = True
        st.last_error = ""
        self._log.info("radar %d connected: %s", st.radar_id, clip(st.url))
        self._on_change()

    def _failed(self, why: str) -> None:
        st = self.status
        changed = st.connected or st.last_error != why
        st.connected = False
        st.last_error = why
        if changed:
            self._log.warning("radar %d (%s) %s; retrying", st.radar_id, clip(st.url), clip(why))
            self._on_change()

    def _firmware(self, port: Any) -> None:
        """Ask the firmware version (enable configuration, 0x00A0, end configuration).

        Serial errors propagate (the port is gone); a sensor that does not
        answer or answers nonsense is read anyway, without light/OUT fields.
        """
        st = self.status
        client = LD2410Client(port, timeout_s=FIRMWARE_TIMEOUT_S, attempts=2)
        try:
            with client.configuring():
                version = client.read_firmware()
        except (RadarError, ProtocolError) as exc:
            if not client.enable_info:
                # The enable ACK may be what got lost: never leave a sensor in
                # configuration mode (it would stop reporting).
                port.write(ld2410.end_config())
            st.firmware = "unknown (no answer)"
            st.light_and_out = False
            self._log.info("radar %d (%s): firmware unknown (%s); light level and OUT pin "
                           "not read", st.radar_id, clip(st.url), clip(str(exc)))
            return
        st.firmware = clip(version, 40)
        st.light_and_out = ld2410.firmware_has_light_and_out(version)
        self._log.info("radar %d firmware %s (light level and OUT pin: %s)", st.radar_id,
                       st.firmware, "yes" if st.light_and_out else "no")

    def _recognised(self, model: str) -> None:
        st = self.status
        if model == st.model:
            return
        if st.model.split()[0] == model.split()[0]:  # LD2410 basic <-> engineering
            st.model = model
            self._on_change()
            return
        if st.model != "unknown":
            st.model_changes += 1
            self._log.warning("radar %d (%s) changed model: %s -> %s", st.radar_id,
                              clip(st.url), st.model, model)
        else:
            self._log.info("radar %d (%s) is an %s", st.radar_id, clip(st.url), model)
        st.model = model
        self._on_change()

    def _read(self, port: Any) -> None:
        # Bytes buffered while nobody read (or before an unplug) are stale.
        with contextlib.suppress(AttributeError, NotImplementedError):
            port.reset_input_buffer()
        st = self.status
        if self._query_firmware:
            self._firmware(port)
        st.last_frame = time.monotonic()
        sniffer = Sniffer(self._model)  # the model is recognised again at every connect
        skipped_at_open = 0
        intact = 0
        while not self._stop.is_set():
            data, stale = fresh_bytes(read_waiting(port, DRAIN_BYTES))
            now = time.monotonic()
            if stale:
                st.stale_bytes += stale
                sniffer.reset()  # what it held does not continue these bytes
            if data:
                stamp = time.time_ns()
                reports, superseded = newest_reports(
                    [f for f in sniffer.feed(data) if describe(f) is not None], stale > 0)
                st.superseded += superseded
                for frame in reports:
                    self._recognised(describe(frame) or "")
                    st.frames += 1
                    if isinstance(frame, Report):
                        st.noise_detection = NOISE_STATES.get(frame.target_state,
                                                              st.noise_detection)
                    self._publish(st.radar_id, frame, stamp)
                if sniffer.intact_frames != intact:
                    # Any intact frame (also one we could not use) shows the line works.
                    intact = sniffer.intact_frames
                    st.last_frame = now
                st.bad_frames = sniffer.bad_frames
                st.unusual_frames = sniffer.unusual_frames
                st.skipped_bytes = sniffer.skipped_bytes
            if now - st.last_frame > self._silence_s:
                hint = " (bytes arrive but never a frame: wrong baud rate, or another model " \
                    "than configured?)" if sniffer.skipped_bytes > skipped_at_open else ""
                raise serial.SerialException(f"no valid frame for {self._silence_s:g} s{hint}")


def fresh_bytes(data: bytes, limit: int = FRESH_BYTES) -> tuple[bytes, int]:
    """(the newest `limit` bytes of what waited, how many older ones are stale)."""
    stale = max(0, len(data) - limit)
    return (data[stale:], stale)


def newest_reports(reports: list[Frame], backlog: bool) -> tuple[list[Frame], int]:
    """(the reports to publish, how many are superseded): all of them, or from a
    backlog only its newest (the others are older news of the same sensor)."""
    if not backlog or len(reports) <= 1:
        return reports, 0
    return reports[-1:], len(reports) - 1


def read_waiting(port: Any, limit: int) -> bytes:
    """What waits on `port`, up to `limit` bytes, in one go (at least one byte, or
    b"" after the port's timeout). pyserial's `socket://` says only whether
    something waits (`in_waiting` is 0 or 1): its non-blocking socket is drained
    directly, else a flood is read a byte at a time and falls behind for good."""
    data = port.read(max(1, min(port.in_waiting, limit)))
    sock = getattr(port, "_socket", None)
    if not data or len(data) >= limit or sock is None:
        return bytes(data)
    try:
        more: bytes = sock.recv(limit - len(data))
    except (BlockingIOError, InterruptedError):
        more = b""
    return bytes(data) + more


class Bridge:
    """The service body: readers + publisher + diagnostics."""

    def __init__(self, node: Node, urls: list[str], device_id: int, baudrate: int,
                 backoff: tuple[float, float], silence_s: float,
                 query_firmware: bool = True, models: list[str] | None = None,
                 mounts: list[Mount] | None = None) -> None:
        self.node = node
        self.device_id = device_id
        self._pub = node.publisher(keys.RADAR_FRAMES, device=str(device_id))
        self._targets_pub = node.publisher(keys.RADAR_TARGETS, device=str(device_id))
        self._mounts = mounts or [IDENTITY] * len(urls)
        models = models or [AUTO] * len(urls)
        self._lock = threading.Lock()
        self._warn = RateLimitedLog(node.log)
        self.publish_errors = 0
        self.readers = [
            SensorReader(url, i, baudrate, self._publish, self._report, node.stop_event,
                         backoff, silence_s, node.log, query_firmware, models[i])
            for i, url in enumerate(urls)
        ]

    def _publish(self, radar_id: int, report: Frame, stamp_ns: int) -> None:
        if isinstance(report, ld2450.Report):
            self._publish_targets(radar_id, report, stamp_ns)
        elif isinstance(report, Report):
            self._publish_frame(radar_id, report, stamp_ns)

    def _put(self, pub: Any, msg: Any) -> None:
        try:
            with self._lock:  # one publisher per key, several reader threads
                pub.put(msg)
        except Exception as exc:  # a Zenoh hiccup must not end the sensor's reader
            self.publish_errors += 1
            self._warn.warning("put", "publishing radar reports failed: %s", clip(repr(exc)))

    def _publish_targets(self, radar_id: int, report: ld2450.Report, stamp_ns: int) -> None:
        converted = report_to_targets(report, self.device_id, radar_id, stamp_ns,
                                      self._mounts[radar_id])
        if converted.implausible:
            self.readers[radar_id].status.implausible_targets += converted.implausible
        self._put(self._targets_pub, converted.message)

    def _publish_frame(self, radar_id: int, report: Report, stamp_ns: int) -> None:
        st = self.readers[radar_id].status
        frame, clamped, bad_out_pin = report_to_frame(report, radar_id, st.light_and_out)
        if clamped:
            st.clamped += clamped
        if bad_out_pin:
            st.bad_out_pin += 1
        msg = m.LD2410TargetDataFrameArray(stamp_ns=stamp_ns, device_id=self.device_id,
                                           sensors=[frame])
        self._put(self._pub, msg)

    def _report(self) -> None:
        """Diagnostics: level from the sensors' connection state, counters per sensor."""
        diag = self.node.diagnostics
        down = [r.status for r in self.readers if not r.status.connected]
        values: dict[str, m.DiagnosticValue] = {"sensors": len(self.readers),
                                                "connected": len(self.readers) - len(down)}
        totals = {"frames": 0, "bad_frames": 0, "reconnects": 0, "clamped_energies": 0,
                  "unusual_frames": 0, "bad_out_pin": 0, "implausible_targets": 0,
                  "stale_bytes": 0, "superseded": 0}
        for r in self.readers:
            st = r.status
            values[f"radar{st.radar_id}.url"] = clip(st.url)
            values[f"radar{st.radar_id}.model"] = st.model
            values[f"radar{st.radar_id}.model_changes"] = st.model_changes
            values[f"radar{st.radar_id}.implausible_targets"] = st.implausible_targets
            values[f"radar{st.radar_id}.firmware"] = st.firmware
            values[f"radar{st.radar_id}.unusual_frames"] = st.unusual_frames
            values[f"radar{st.radar_id}.bad_out_pin"] = st.bad_out_pin
            if st.noise_detection:
                values[f"radar{st.radar_id}.noise_detection"] = st.noise_detection
            values[f"radar{st.radar_id}.connected"] = st.connected
            values[f"radar{st.radar_id}.frames"] = st.frames
            values[f"radar{st.radar_id}.bad_frames"] = st.bad_frames
            values[f"radar{st.radar_id}.skipped_bytes"] = st.skipped_bytes
            values[f"radar{st.radar_id}.stale_bytes"] = st.stale_bytes
            values[f"radar{st.radar_id}.superseded"] = st.superseded
            values[f"radar{st.radar_id}.reconnects"] = st.reconnects
            values[f"radar{st.radar_id}.clamped_energies"] = st.clamped
            totals["frames"] += st.frames
            totals["bad_frames"] += st.bad_frames
            totals["reconnects"] += st.reconnects
            totals["clamped_energies"] += st.clamped
            totals["unusual_frames"] += st.unusual_frames
            totals["bad_out_pin"] += st.bad_out_pin
            totals["implausible_targets"] += st.implausible_targets
            totals["stale_bytes"] += st.stale_bytes
            totals["superseded"] += st.superseded
            if st.last_error:
                values[f"radar{st.radar_id}.error"] = clip(st.last_error)
        values.update(totals)
        values["publish_errors"] = self.publish_errors
        diag.values = values  # one reference swap: the publisher copies it
        if not down:
            diag.set("OK", f"{len(self.readers)} sensor(s) connected")
        elif all(s.last_error == "connecting" for s in down):
            diag.set("WARN", f"connecting to {len(down)} sensor(s)")
        else:
            text = "; ".join(f"radar {s.radar_id} ({clip(s.url, 80)}) down: {clip(s.last_error)}"
                             for s in down)
            diag.set("ERROR" if len(down) == len(self.readers) else "WARN", text)
        diag.publish()

    def start(self) -> None:
        self._report()
        for r in self.readers:
            r.thread.start()
        self.node.every(1.0, self._report, name="radar-diagnostics")

    def join(self) -> None:
        for r in self.readers:
            r.thread.join(2)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Every option overrides a `[radar_bridge]` key (defaults and ranges: settings.py)."""
    option = RadarBridgeSettings
    settings_option(parser, "--sensor", struct=option, field="sensors", metavar="URL",
                    help="pyserial URL of a sensor, repeatable, replacing the configured "
                         "list; radar_id = order (e.g. /dev/ttyUSB0, "
                         "socket://esp32.local:8881, rfc2217://h:p)")
    settings_option(parser, "--device-id", struct=option, field="device_id")
    settings_option(parser, "--baudrate", struct=option, field="baudrate")
    settings_option(parser, "--sim", struct=option, field="sim",
                    action=argparse.BooleanOptionalAction)
    settings_option(parser, "--sim-model", struct=option, field="sim_model",
                    choices=list(MODELS))
    add_world_arguments(parser)


@dataclass(frozen=True)
class BridgeOptions:
    """What `run` starts: command line merged over `[radar_bridge]`."""

    urls: list[str]
    device_id: int
    baudrate: int
    sim: bool  # a simulated sensor of the world in `[sim]`, last
    sim_model: str = "LD2410"
    models: list[str] = field(default_factory=list)  # per sensor (the sim last)
    mounts: list[Mount] = field(default_factory=list)  # per sensor (the sim last)


def merged_settings(args: argparse.Namespace, cfg: RadarBridgeSettings) -> RadarBridgeSettings:
    """`[radar_bridge]` with the command line on top: what the bridge runs with.

    Ranges (`--baudrate 0`) are refused by `merge` naming
    the flag, and so is a network URL that can never open (`urls.py`: a
    `socket://` without its port would otherwise be retried forever). One
    rule is more than a field set: with the simulated sensor on
    (flag or config), configured hardware is left alone, unless sensors were
    given explicitly with `--sensor` (those are read alongside it).
    """
    s = merge(cfg, args)
    for i, url in enumerate(s.sensors):
        if (problem := url_problem(url)) is not None:
            where = "--sensor" if given(args, RadarBridgeSettings, "sensors") \
                else f"radar_bridge.sensors[{i}]"
            raise ConfigError(f"{where}: {clip(url, 80)}: {problem}")
    if s.sim and not given(args, RadarBridgeSettings, "sensors"):
        s = msgspec.structs.replace(s, sensors=[])
    if s.sim_model not in MODELS:
        raise ConfigError(f"radar_bridge.sim_model: unknown {s.sim_model!r}; one of "
                          f"{list(MODELS)}")
    per_sensor(s)
    return s


def _count(s: RadarBridgeSettings) -> int:
    return len(s.sensors) + (1 if s.sim else 0)


def per_sensor(s: RadarBridgeSettings) -> tuple[list[str], list[Mount]]:
    """Each sensor's model setting and mount, by index (the simulated sensor last).

    ConfigError, naming the key, for a model that is not one, an index that is
    no sensor, or two mounts for one sensor.
    """
    count = _count(s)
    models = [AUTO] * count
    for key, model in s.models.items():
        if not key.isdigit() or int(key) >= count:
            raise ConfigError(f"radar_bridge.models: {key!r} is not a sensor index "
                              f"(0..{count - 1}; there are {count} sensor(s))")
        if model not in (AUTO, *MODELS):
            raise ConfigError(f"radar_bridge.models.{key}: unknown model {model!r}; one "
                              f"of {[AUTO, *MODELS]}")
        models[int(key)] = model
    if s.sim:
        models[-1] = s.sim_model
    mounts = [IDENTITY] * count
    seen: set[int] = set()
    for n, entry in enumerate(s.mount):
        where = f"radar_bridge.mount[{n}].sensor"
        if entry.sensor >= count:
            raise ConfigError(f"{where}: {entry.sensor} is not a sensor index "
                              f"(0..{count - 1}; there are {count} sensor(s))")
        if entry.sensor in seen:
            raise ConfigError(f"{where}: sensor {entry.sensor} has two mounts")
        seen.add(entry.sensor)
        mounts[entry.sensor] = Mount(entry.x, entry.y, entry.z, entry.yaw, entry.mirror_x)
    return models, mounts


def settings_from(ctx: ServiceContext) -> RadarBridgeSettings:
    """The settings `run` starts the bridge with (tests check they reach it)."""
    return merged_settings(ctx.args, ctx.config.section(RadarBridgeSettings))


def options_from(s: RadarBridgeSettings) -> BridgeOptions:
    """What to open: the sensors, plus the simulated one when `sim` is on."""
    models, mounts = per_sensor(s)
    return BridgeOptions(list(s.sensors), s.device_id, s.baudrate, s.sim, s.sim_model,
                         models, mounts)


def resolve_options(args: argparse.Namespace, cfg: RadarBridgeSettings) -> BridgeOptions:
    """Command line merged over the config, as the sensors to open (pure, for tests)."""
    return options_from(merged_settings(args, cfg))


def run(ctx: ServiceContext) -> int:
    from buddybot.radar.sim import PtySensor

    cfg = settings_from(ctx)
    opts = options_from(cfg)
    urls = list(opts.urls)
    sims: list[PtySensor] = []
    if opts.sim:
        world, clock, _ = world_from(ctx)
        script = world_script(world, opts.sim_model, opts.mounts[-1])
        sims.append(PtySensor(script, model=opts.sim_model, clock=clock.now).start())
        urls.append(sims[-1].path)
    if not urls:
        raise UsageError("no sensor: give --sensor URL (repeatable) or --sim")
    node = ctx.node()
    LiveSettings(cfg).serve(node)  # readable and dumpable; every field needs a restart
    bridge = Bridge(node, urls, opts.device_id, opts.baudrate,
                    (cfg.reconnect_initial_s, cfg.reconnect_max_s),
                    cfg.silence_timeout_s, cfg.query_firmware, opts.models, opts.mounts)
    try:
        bridge.start()
        node.spin()
    finally:
        node.stop()
        bridge.join()
        node.close()
        for sim in sims:
            sim.stop()
    return 0
