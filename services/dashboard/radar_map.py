"""What the top-down map shows: angle-radar targets and trails, zones, the camera's
view and the followed person, as canvas primitives for the page to paint.

`RadarMap` remembers the newest report of every angle radar
(`radar/{device}/targets`) and every target position of the last `trail_s`
seconds, the presence zones, the camera's field of view, `people/state`
and whom the controller follows (`controller/state` person_id). `scene`
turns it into what the page paints, in canvas pixels
(`map_geometry.fit_view` chooses the view). While the robot is simulated it
also draws the simulated world's truth (`sim/world`) beside what the robot
perceives. No Zenoh, threads or clocks:
the caller passes its clock (the dashboard's arrival time, so a sender
with a skewed clock still ages out on time).

Trails are drawn per sensor slot, broken where a slot jumps (the LD2450's
slots swap between people) or pauses: the dashboard draws where targets
were and does not track people (the tracker does).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, cast

import msgspec

from buddybot.contract import messages as m
from buddybot.dashboard import map_geometry as geo
from buddybot.runtime.limits import BoundedDict

TRAIL_S = 3.0
"""Seconds of positions drawn behind each target."""
STALE_S = 1.0
"""A sensor silent this long shows no targets (its trail fades as usual)."""
FORGET_S = 60.0
"""A sensor silent this long leaves the map's legend."""
MAX_STEP_M = 0.6
"""A slot moving farther than this between reports is another person: the trail breaks."""
MAX_GAP_S = 0.6
"""Nor are reports further apart than this joined."""
MAX_TRAIL_POINTS = 400
"""Positions kept per sensor (3 targets x 10 Hz x 3 s is 90)."""
MAX_ZONES = 16
MAP_SIZE = (800, 660)
"""The map canvas in pixels (drawn at half size: sharp on a high-density screen)."""

ZoneMode = Literal["detect", "ignore"]


@dataclass(frozen=True)
class Zone:
    """A presence zone: a rectangle of the camera's frame (x forward, y left, metres)."""

    mode: ZoneMode
    x_min: float
    x_max: float
    y_min: float
    y_max: float
    name: str = ""


def _span(value: Any) -> tuple[float, float] | None:
    """A zone's `[low, high]` metres, in either order; None unless two finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        return None
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
               for v in value):
        return None
    low, high = float(value[0]), float(value[1])
    return (min(low, high), max(low, high))


def parse_zones(value: Any) -> list[Zone] | None:
    """`[radar_presence] zones` (radar-presence's live parameter or the config
    table's field, as plain data) -> zones; None when there is no such list.

    A zone is a table `{name, mode, x = [near, far], y = [right, left]}`
    (metres of the camera's frame, as radar-presence reads it; mode `detect`
    or `ignore`). The dashboard only draws them: a zone it cannot read is
    skipped, so one bad zone never hides the others.
    """
    if isinstance(value, msgspec.Struct):
        value = msgspec.to_builtins(value)
    if not isinstance(value, list):
        return None
    out: list[Zone] = []
    for item in value[:MAX_ZONES]:
        if isinstance(item, msgspec.Struct):
            item = msgspec.to_builtins(item)
        if not isinstance(item, dict):
            continue
        mode = item.get("mode")
        x, y = _span(item.get("x")), _span(item.get("y"))
        if mode not in ("detect", "ignore") or x is None or y is None:
            continue
        name = item.get("name")
        out.append(Zone(cast(ZoneMode, mode), x[0], x[1], y[0], y[1],
                        name[:40] if isinstance(name, str) else ""))
    return out


def params_value(reply: m.ParamReply | None, name: str) -> Any:
    """One field's value from a `params` reply; None when absent or refused."""
    if reply is None or reply.error:
        return None
    for p in reply.params:
        if p.name == name:
            return p.value
    return None


def number_params(reply: m.ParamReply | None, names: tuple[str, ...]) -> dict[str, float]:
    """The finite numbers among `names` in a `params` reply (None values left out)."""
    out: dict[str, float] = {}
    for name in names:
        v = params_value(reply, name)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            out[name] = float(v)
    return out


CAMERA_FIELDS = ("fx", "cx", "hfov_deg")
"""The face detector's intrinsics the map's field of view is drawn from."""


@dataclass
class _Sensor:
    index: int
    """Its colour on the page (the order sensors were first seen)."""
    last_s: float
    targets: list[m.RadarTarget]
    trail: deque[tuple[float, int, float, float]]
    """(t, slot, x, y) of every target of the last `trail_s`."""


class RadarMap:
    """Everything the map draws, kept between messages (bounded)."""

    def __init__(self, trail_s: float = TRAIL_S, max_sensors: int = 32) -> None:
        self.trail_s = trail_s
        self._sensors: BoundedDict[str, _Sensor] = BoundedDict(max_sensors)
        self._seen = 0
        self.zones: list[Zone] = []
        self.zones_from = ""
        self.fov: tuple[float, float] | None = None
        self.fov_from = ""
        self.people: m.PeopleState | None = None
        self.controller: m.ControllerState | None = None
        self.truth: m.SimWorld | None = None
        self.truth_s = -math.inf

    def __bool__(self) -> bool:
        """Whether an angle radar or a simulated world was heard (the page shows the map
        only then)."""
        return bool(self._sensors) or self.truth is not None

    def set_truth(self, msg: m.SimWorld, now_s: float) -> None:
        self.truth, self.truth_s = msg, now_s

    def _fresh_truth(self, now_s: float) -> m.SimWorld | None:
        return self.truth if now_s - self.truth_s <= STALE_S else None

    def add(self, msg: m.RadarTargets, now_s: float) -> None:
        key = f"{msg.device_id}/{msg.radar_id}"
        s = self._sensors.get(key)
        if s is None:
            s = self._sensors[key] = _Sensor(self._seen, now_s, [], deque(
                maxlen=MAX_TRAIL_POINTS))
            self._seen += 1
        s.last_s = now_s
        s.targets = list(msg.targets)
        for t in msg.targets:
            s.trail.append((now_s, t.slot, t.position.x, t.position.y))
        self._trim(now_s)

    def _trim(self, now_s: float) -> None:
        for key, s in list(self._sensors.items()):
            while s.trail and s.trail[0][0] < now_s - self.trail_s:
                s.trail.popleft()
            if now_s - s.last_s > FORGET_S:
                del self._sensors[key]

    def set_zones(self, zones: list[Zone], source: str) -> None:
        self.zones, self.zones_from = zones, source

    def set_fov(self, fov: tuple[float, float] | None, source: str) -> None:
        self.fov, self.fov_from = fov, source

    def followed(self) -> m.Person | None:
        """The person the controller's visit is about, from `people/state`."""
        c, p = self.controller, self.people
        if c is None or c.person_id is None or p is None:
            return None
        return next((x for x in p.people if x.id == c.person_id), None)

    # -- the scene --

    def _world_points(self, now_s: float) -> list[tuple[float, float]]:
        pts = [(x, y) for s in self._sensors.values() for _t, _slot, x, y in s.trail]
        pts += [(t.position.x, t.position.y) for s in self._sensors.values()
                if now_s - s.last_s <= STALE_S for t in s.targets]
        for z in self.zones:
            pts += [(x, y) for x in (z.x_min, z.x_max) for y in (z.y_min, z.y_max)]
        for person in (self.people.people if self.people else []):
            if person.yaw_rad is not None:
                pts.append(geo.bearing_point(person.yaw_rad, person.distance_m))
        truth = self._fresh_truth(now_s)
        if truth is not None:
            pts += [(p.position.x, p.position.y) for p in truth.people]
            pts += [(c.position.x, c.position.y) for c in truth.clutter]
        return pts

    def scene(self, now_s: float, size: tuple[int, int] = MAP_SIZE) -> dict[str, Any] | None:
        """What the page paints now (canvas pixels), or None before any angle radar."""
        self._trim(now_s)
        if not self:
            return None
        view = geo.fit_view(size[0], size[1], self._world_points(now_s))
        px = _px(view)
        sensors = []
        for key, s in self._sensors.items():
            fresh = now_s - s.last_s <= STALE_S
            sensors.append({
                "key": key, "index": s.index, "silent": not fresh,
                "targets": [{
                    "slot": t.slot, "at": px(t.position.x, t.position.y),
                    "distance_m": round(t.distance_m, 2),
                    "bearing_deg": round(math.degrees(t.bearing_rad), 1),
                    "speed_mps": round(t.speed_mps, 2),
                } for t in (s.targets if fresh else [])],
                "trails": _trails(s.trail, px),
            })
        zones = [{"mode": z.mode, "name": z.name,
                  "poly": [[round(u, 1), round(v, 1)] for u, v in
                           geo.rectangle(view, z.x_min, z.x_max, z.y_min, z.y_max)]}
                 for z in self.zones]
        fov = None
        if self.fov is not None:
            left, right = self.fov
            fov = {"poly": [[round(u, 1), round(v, 1)] for u, v in geo.wedge(view, left, right)],
                   "hfov_deg": round(math.degrees(left - right), 1), "from": self.fov_from}
        followed = self.followed()
        people = [_person(p, view, followed is not None and p.id == followed.id)
                  for p in (self.people.people if self.people else [])]
        return {
            "size": list(size), "origin": px(0.0, 0.0), "scale": round(view.scale, 3),
            "rings": [{"m": r, "px": round(r * view.scale, 1)} for r in geo.rings(view)],
            "sensors": sensors, "zones": zones, "zones_from": self.zones_from, "fov": fov,
            "people": people, "trail_s": self.trail_s,
            "truth": _truth(self._fresh_truth(now_s), view),
        }


def _px(view: geo.MapView) -> Any:
    def at(x: float, y: float) -> list[float]:
        u, v = view.to_canvas(x, y)
        return [round(u, 1), round(v, 1)]
    return at


def _trails(trail: deque[tuple[float, int, float, float]], px: Any) -> list[list[list[float]]]:
    """Polylines per slot, [u, v, t] each point (t: the dashboard's clock, so the
    page fades them by age), broken at jumps and pauses."""
    by_slot: dict[int, list[list[tuple[float, float, float]]]] = {}
    for t, slot, x, y in trail:
        runs = by_slot.setdefault(slot, [])
        last = runs[-1][-1] if runs else None
        if last is None or t - last[0] > MAX_GAP_S \
                or math.hypot(x - last[1], y - last[2]) > MAX_STEP_M:
            runs.append([])
        runs[-1].append((t, x, y))
    out = []
    for runs in by_slot.values():
        for run in runs:
            if len(run) >= 2:
                out.append([[*px(x, y), round(t, 2)] for t, x, y in run])
    return out


def _person(p: m.Person, view: geo.MapView, followed: bool) -> dict[str, Any]:
    """A person: at their bearing when known, else a ring at their distance."""
    at = None
    if p.yaw_rad is not None:
        u, v = view.to_canvas(*geo.bearing_point(p.yaw_rad, p.distance_m))
        at = [round(u, 1), round(v, 1)]
    return {"id": p.id, "followed": followed, "at": at,
            "ring_px": round(p.distance_m * view.scale, 1),
            "distance_m": round(p.distance_m, 2), "seen_by": p.seen_by,
            "yaw_deg": None if p.yaw_rad is None else round(math.degrees(p.yaw_rad), 1),
            "name": p.name}


def _truth(world: m.SimWorld | None, view: geo.MapView) -> dict[str, Any] | None:
    """The simulated world's people and clutter where they really are, each person
    with a short arrow where they face and which sensors should see them."""
    if world is None:
        return None
    at = _px(view)
    people = [{
        "id": p.id, "name": p.name, "at": at(p.position.x, p.position.y),
        "facing": at(p.position.x + 0.35 * math.cos(p.facing_rad),
                     p.position.y + 0.35 * math.sin(p.facing_rad)),
        "in_radar": p.in_radar, "in_camera": p.in_camera,
    } for p in world.people]
    clutter = [{"kind": c.kind, "at": at(c.position.x, c.position.y)} for c in world.clutter]
    return {"scenario": world.scenario, "t_s": round(world.t_s, 1), "people": people,
            "clutter": clutter}


# --- where the zones and the field of view come from ------------------------------------

PRESENCE_PARAMS = "params/radar-presence"
DETECTOR_PARAMS = "params/face-detector"


@dataclass(frozen=True)
class Configured:
    """What this machine's config says, for when the services do not answer."""

    zones: list[Zone] | None = None
    camera: Mapping[str, float] = field(default_factory=dict)
    width: int | None = None

    @staticmethod
    def read(config: Any) -> Configured:
        """From the config's `[radar_presence]`, `[face_detector]` and `[camera]`
        tables, read by name (the dashboard imports no other area); a field a
        table lacks is simply not known."""
        presence = getattr(config, "radar_presence", None)
        detector = getattr(config, "face_detector", None)
        camera = getattr(config, "camera", None)
        numbers = {}
        for name in CAMERA_FIELDS:
            v = getattr(detector, name, None)
            if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                numbers[name] = float(v)
        width = getattr(camera, "width", None)
        return Configured(parse_zones(getattr(presence, "zones", None)), numbers,
                          width if isinstance(width, int) and width > 0 else None)


def choose_zones(live: list[Zone] | None, configured: list[Zone] | None) -> tuple[list[Zone], str]:
    """The zones radar-presence runs with (its live `zones` parameter), else this
    machine's `[radar_presence] zones`; with where they came from."""
    if live is not None:
        return live, PRESENCE_PARAMS
    if configured is not None:
        return configured, "[radar_presence] zones of this machine's config"
    return [], ""


def choose_fov(live: Mapping[str, float] | None, configured: Mapping[str, float],
               width_px: int | None) -> tuple[tuple[float, float] | None, str]:
    """The camera's view from the face detector's intrinsics: its live parameters
    when it answers, else this machine's `[face_detector]`; the frame width from
    its `faces` (else `[camera] width`). With a line saying where it came from."""
    params, where = ((live, DETECTOR_PARAMS) if live is not None
                     else (configured, "[face_detector] of this machine's config"))
    fov = geo.camera_fov(width_px, params.get("fx"), params.get("cx"), params.get("hfov_deg"))
    if fov is None:
        return None, f"unknown ({where} gives no hfov_deg, and no frame width is known yet)"
    if "hfov_deg" in params:
        how = f"hfov_deg {params['hfov_deg']:g}"
    else:
        how = f"fx {params['fx']:g} px over {width_px} px"
    return fov, f"{where}: {how}"
