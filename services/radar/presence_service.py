"""`buddybot run radar-presence`: radar frames of every bridge -> `radar/presence` (latched).

The seed's radar_hld as a thin adapter around `presence.PresenceTracker`:
frames arrive from all devices (wildcard subscription), each sensor is
known as "<device>/<radar_id>", a timer drives the hold and staleness
rules, and a change is published at once, stamped with the frame that
caused it. Stale sensors are reported in `diagnostics/radar-presence`.
"""

from __future__ import annotations

import argparse
import threading
import time

from buddybot.core import keys
from buddybot.core import messages as m
from buddybot.core.config import ConfigError
from buddybot.core.node import Node
from buddybot.core.service import ServiceContext
from buddybot.radar.presence import PresenceRules, PresenceTracker, Reading, Verdict
from buddybot.radar.settings import RadarPresenceSettings

TICK_S = 0.05  # hold/staleness resolution; costs nothing, keeps OUT_OF_RANGE on time


def rules_from(cfg: RadarPresenceSettings, args: argparse.Namespace) -> PresenceRules:
    """Config table, then command-line overrides."""
    values = {name: getattr(cfg, name) for name in (
        "range_m", "exit_margin_m", "absence_hold_s", "target_hold_s", "stale_after_s")}
    for name in values:
        override = getattr(args, name, None)
        if override is not None:
            values[name] = override
    try:
        return PresenceRules(**values)
    except ValueError as exc:
        raise ConfigError(f"radar_presence: {exc}") from None


class PresenceService:
    def __init__(self, node: Node, rules: PresenceRules) -> None:
        self.node = node
        self.tracker = PresenceTracker(rules)
        self._lock = threading.Lock()
        self._pub = node.publisher(keys.PRESENCE)
        self._stale: list[str] | None = None
        self._known: list[str] = []
        self._published = 0

    def on_frames(self, msg: m.LD2410TargetDataFrameArray, key: str) -> None:
        now = time.monotonic()
        # The key names the bridge (the payload's device_id should agree; the key wins).
        device = (keys.RADAR_FRAMES.match(key) or {}).get("device", str(msg.device_id))
        with self._lock:
            for frame in msg.sensors:
                reading = Reading(int(frame.target_state), frame.detection_distance,
                                  frame.movement_distance, frame.stationary_distance)
                verdict = self.tracker.update(f"{device}/{frame.radar_id}", reading,
                                              now, msg.stamp_ns)
                if verdict is not None:
                    self._publish(verdict)

    def tick(self) -> None:
        now = time.monotonic()
        with self._lock:
            verdict = self.tracker.tick(now)
            if verdict is not None:
                self._publish(verdict)
            stale = self.tracker.stale_sensors(now)
            known = self.tracker.known_sensors()
        if stale != self._stale or known != self._known:
            self._stale, self._known = stale, known
            self._report(known, stale)

    def _publish(self, v: Verdict) -> None:
        self._published += 1
        self._pub.put(m.PresenceDetection(stamp_ns=v.stamp_ns, target_state=v.target,
                                          presence_state=v.presence, distance_m=v.distance_m))
        self.node.log.info("presence %s %s at %.2f m", v.presence.name, v.target.name,
                           v.distance_m)
        self.node.diagnostics.values["presence"] = v.presence.name
        self.node.diagnostics.values["changes"] = self._published

    def _report(self, known: list[str], stale: list[str]) -> None:
        diag = self.node.diagnostics
        diag.values["sensors"] = len(known)
        diag.values["stale"] = ",".join(stale)
        if not known:
            diag.set("WARN", "waiting for radar frames")
        elif not stale:
            diag.set("OK", f"{len(known)} sensor(s) fresh")
        elif len(stale) == len(known):
            diag.set("ERROR", f"no radar data: all sensors silent ({', '.join(stale)}); "
                              "keeping the last verdict")
        else:
            diag.set("WARN", f"sensor(s) silent, excluded: {', '.join(stale)}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--range-m", dest="range_m", type=float,
                        help="IN_RANGE within this distance (default 2.0)")
    parser.add_argument("--exit-margin-m", dest="exit_margin_m", type=float,
                        help="leave only beyond range + margin (default 0.3)")
    parser.add_argument("--absence-hold-s", dest="absence_hold_s", type=float,
                        help="nobody in range this long before OUT_OF_RANGE (default 3.0)")
    parser.add_argument("--target-hold-s", dest="target_hold_s", type=float,
                        help="MOVING/STANDING change must last this long (default 1.0)")
    parser.add_argument("--stale-after-s", dest="stale_after_s", type=float,
                        help="a sensor silent this long is excluded (default 1.5)")


def run(ctx: ServiceContext) -> int:
    rules = rules_from(ctx.config.radar_presence, ctx.args)
    node = ctx.node()
    try:
        service = PresenceService(node, rules)
        # Every device (wildcard); on a worker, never in Zenoh's thread.
        node.subscribe(keys.RADAR_FRAMES, service.on_frames, delivery="queue", queue_size=256)
        node.every(TICK_S, service.tick, name="presence-tick")
        node.spin()
    finally:
        node.close()
    return 0
