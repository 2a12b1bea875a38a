"""`buddybot run radar-presence`: radar reports of every bridge -> `radar/presence` (latched).

A thin adapter around `presence.PresenceTracker`:
LD2410 frames (`radar/*/frames`) and LD2450 targets (`radar/*/targets`)
arrive from all devices (wildcard subscriptions), each sensor is known as
"<device>/<radar_id>" whatever its model, a timer drives the hold and staleness
rules, and a change is published at once, stamped with the frame that
caused it. Stale sensors are reported in `diagnostics/radar-presence`.

Everything here comes from the network, so everything is bounded: the
sensor table (`max_sensors`), the frames taken from one message (a bridge
sends one sensor per message; at most `max_sensors`), the diagnostics
(counts and a few clipped names, at most one change report per second),
and stamps (a frame stamped outside [now - 10 s, now + 1 s] is taken at
its arrival time, and no verdict is published with an implausible
stamp). Frames reach the rule through an `Intake`: keys carrying an
established sensor are served first, so a flood on other keys can delay
or drop only the flood.
"""

from __future__ import annotations

import argparse
import threading
import time

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar.intake import Intake
from buddybot.radar.presence import PresenceTracker, Reading, Verdict, read_targets
from buddybot.radar.settings import RadarPresenceSettings
from buddybot.runtime.limits import clip, plausible_stamp
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.service import ServiceContext

TICK_S = 0.05  # hold/staleness resolution; costs nothing, keeps OUT_OF_RANGE on time
REPORT_MIN_S = 1.0  # a changing sensor list is reported at most this often (level: at once)
NAMES_SHOWN = 4  # sensor names listed in diagnostics; the rest are counted
NAME_MAX = 60  # characters of a sensor name (the device part comes from the key)
QUEUE_SIZE = 256  # frames from not (yet) established sensors waiting for the rule
RULE_NAMES = ("range_m", "exit_margin_m", "absence_hold_s", "target_hold_s", "stale_after_s",
              "max_sensors", "moving_speed_mps")
Report = m.LD2410TargetDataFrameArray | m.RadarTargets


def settings_from(ctx: ServiceContext) -> RadarPresenceSettings:
    """`[radar_presence]` with the command line on top: what `run` builds the rules from."""
    return merge(ctx.config.section(RadarPresenceSettings), ctx.args)


class PresenceService:
    def __init__(self, node: Node, rules: RadarPresenceSettings) -> None:
        self.node = node
        self.tracker = PresenceTracker(rules)
        self._lock = threading.Lock()
        self._pub = node.publisher(keys.PRESENCE)
        self._stale: list[str] | None = None
        self._known: list[str] = []
        self._level = ""
        self._reported_at = 0.0
        self._published = 0
        self.implausible_stamps = 0
        self.ignored_frames = 0
        self.zone_ignored = 0
        """Angle-radar targets inside an ignore zone (each report counts again)."""
        self.zone_outside = 0
        """Angle-radar targets outside every detect zone."""
        self.intake: Intake[Report] = Intake(
            self._take, general_size=QUEUE_SIZE, per_key=rules.max_sensors,
            max_trusted=rules.max_sensors, on_error=self._handler_failed,
            name="presence-intake")

    def apply_settings(self, rules: RadarPresenceSettings) -> None:
        """A live parameter change (`buddybot param set radar-presence ...`): the
        tracker reads its rules on every frame and tick, so the next one uses
        them. `max_sensors` sized the tables at start: it is restart-only."""
        with self._lock:
            self.tracker.rules = rules

    def submit(self, msg: Report, key: str) -> None:
        """In Zenoh's thread: only sorted into the intake (frames and targets
        come on different keys, so each has its own lane once trusted)."""
        self.intake.submit(key, msg)

    def _take(self, key: str, msg: Report) -> None:
        if isinstance(msg, m.RadarTargets):
            self.on_targets(msg, key)
        else:
            self.on_frames(msg, key)

    def _handler_failed(self, exc: BaseException) -> None:
        self.node.diagnostics.increment("callback_errors")
        self.node.log.warning("presence handler failed: %s", clip(repr(exc)))

    def on_frames(self, msg: m.LD2410TargetDataFrameArray, key: str) -> None:
        now = time.monotonic()
        # A wrong clock (or an attacker) must not put its stamp on our verdicts.
        stamp, replaced = plausible_stamp(msg.stamp_ns, m.now_ns())
        # The key names the bridge (the payload's device_id should agree; the key wins).
        device = (keys.RADAR_FRAMES.match(key) or {}).get("device", str(msg.device_id))
        limit = self.tracker.rules.max_sensors
        with self._lock:
            if replaced:
                self.implausible_stamps += 1
            if len(msg.sensors) > limit:
                self.ignored_frames += len(msg.sensors) - limit
            trusted = False
            for frame in msg.sensors[:limit]:
                reading = Reading(int(frame.target_state), frame.detection_distance,
                                  frame.movement_distance, frame.stationary_distance)
                name = clip(f"{device}/{frame.radar_id}", NAME_MAX)
                verdict = self.tracker.update(name, reading, now, stamp)
                if verdict is not None:
                    self._publish(verdict)
                trusted = trusted or self.tracker.established(name)
        if trusted:
            self.intake.trust(key)

    def on_targets(self, msg: m.RadarTargets, key: str) -> None:
        """One LD2450 report: the targets the zones count make one sensor's reading."""
        now = time.monotonic()
        stamp, replaced = plausible_stamp(msg.stamp_ns, m.now_ns())
        device = (keys.RADAR_TARGETS.match(key) or {}).get("device", str(msg.device_id))
        name = clip(f"{device}/{msg.radar_id}", NAME_MAX)
        with self._lock:
            if replaced:
                self.implausible_stamps += 1
            reading = read_targets(msg.targets, self.tracker.rules)
            self.zone_ignored += reading.ignored
            self.zone_outside += reading.outside
            verdict = self.tracker.update(name, reading, now, stamp)
            if verdict is not None:
                self._publish(verdict)
            trusted = self.tracker.established(name)
        if trusted:
            self.intake.trust(key)

    def tick(self) -> None:
        now = time.monotonic()
        with self._lock:
            verdict = self.tracker.tick(now)
            if verdict is not None:
                self._publish(verdict)
            stale = self.tracker.stale_sensors(now)
            known = self.tracker.known_sensors()
            values = self.node.diagnostics.values
            values["evicted_sensors"] = self.tracker.evicted
            values["implausible_stamps"] = self.implausible_stamps
            values["ignored_frames"] = self.ignored_frames
            values["targets_in_ignore_zones"] = self.zone_ignored
            values["targets_outside_detect_zones"] = self.zone_outside
            values["dropped_frames"] = self.intake.dropped
            values["dropped_established_frames"] = self.intake.dropped_trusted
        if stale == self._stale and known == self._known:
            return
        level = _level(known, stale)
        # Under a flood of sensor ids the lists change every tick: report a new
        # level at once, a new list at most once per REPORT_MIN_S.
        if level == self._level and now - self._reported_at < REPORT_MIN_S:
            return
        self._stale, self._known, self._level, self._reported_at = stale, known, level, now
        self._report(known, stale, level)

    def _publish(self, v: Verdict) -> None:
        self._published += 1
        # Frame stamps were checked on arrival; this is the last line of defence.
        stamp, replaced = plausible_stamp(v.stamp_ns, m.now_ns())
        if replaced:
            self.implausible_stamps += 1
        self._pub.put(m.PresenceDetection(stamp_ns=stamp, target_state=v.target,
                                          presence_state=v.presence, distance_m=v.distance_m))
        self.node.log.info("presence %s %s at %.2f m", v.presence.name, v.target.name,
                           v.distance_m)
        self.node.diagnostics.values["presence"] = v.presence.name
        self.node.diagnostics.values["changes"] = self._published

    def _report(self, known: list[str], stale: list[str], level: str) -> None:
        diag = self.node.diagnostics
        diag.values["sensors"] = len(known)
        diag.values["stale_count"] = len(stale)
        diag.values["stale"] = _names(stale)
        if level == "WAIT":
            diag.set("WARN", "waiting for radar frames")
        elif level == "OK":
            diag.set("OK", f"{len(known)} sensor(s) fresh")
        elif level == "ERROR":
            diag.set("ERROR", f"no radar data: all sensors silent ({_names(stale)}); "
                              "keeping the last verdict")
        else:
            diag.set("WARN", f"{len(stale)} of {len(known)} sensor(s) silent, excluded: "
                             f"{_names(stale)}")


def _level(known: list[str], stale: list[str]) -> str:
    if not known:
        return "WAIT"
    if not stale:
        return "OK"
    return "ERROR" if len(stale) == len(known) else "WARN"


def _names(names: list[str]) -> str:
    """A few names and a count: diagnostics stay small whatever the network sends."""
    shown = ", ".join(names[:NAMES_SHOWN])
    more = len(names) - NAMES_SHOWN
    return f"{shown} (+{more} more)" if more > 0 else shown


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """One option per rule, each overriding its `[radar_presence]` key."""
    for name in RULE_NAMES:
        settings_option(parser, "--" + name.replace("_", "-"), struct=RadarPresenceSettings,
                        field=name)


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)
    node = ctx.node()
    try:
        service = PresenceService(node, settings)
        LiveSettings(settings, service.apply_settings).serve(node)
        service.intake.start()
        # Every device (wildcard), both models. Zenoh's thread only sorts the
        # reports into the intake; the rule runs on its worker, established
        # sensors first.
        node.subscribe(keys.RADAR_FRAMES, service.submit, delivery="inline")
        node.subscribe(keys.RADAR_TARGETS, service.submit, delivery="inline")
        node.every(TICK_S, service.tick, name="presence-tick")
        try:
            node.spin()
        finally:
            service.intake.close()
    finally:
        node.close()
    return 0
