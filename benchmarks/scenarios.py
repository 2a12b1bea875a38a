"""Benchmark: what the simulated robot perceives against the simulated world's truth.

For each scenario, starts `buddybot up --sim --scenario NAME` on private
loopback ports (the whole robot, every service its own process), records
`sim/world` (the truth) beside what the robot made of it, and prints per
scenario:

- faces: how many face positions, and their distance and bearing error
  against the person the truth puts nearest that bearing (median / p95);
- radar (LD2450 scenarios): each target's error against the nearest person;
- timing: from a person coming within 2 m (truth) to the people service's
  `ARRIVED`, from their leaving to `LEFT`, and to the start of the farewell
  (the median over the visits seen), how many greetings the visits got, and
  how many engagement changes each person made (median; a calm visit makes
  about five: ENGAGING, ENGAGED, DISENGAGING, NONE, GONE).

`out_of_view` runs with a simulated LD2450 (it needs a bearing radar), the
rest with the default LD2410.

    .venv/bin/python benchmarks/scenarios.py [--scenario NAME ...] [--laps N]
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import results
from common import percentile

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import available_services
from buddybot.sim import scenario as scenarios
from buddybot.tools.testing import Collector, Process, buddybot_argv, free_port

RANGE_M = 2.0
"""The presence radar's default range: within it a person is "there"."""
DEFAULT = ("visit", "passer_by", "two_people", "out_of_view", "return", "dark", "crowd",
           "ghost")
MAX_S = 240.0
LD2450_SCENARIOS = {"out_of_view"}


@dataclass
class Record:
    truth: list[m.SimWorld] = field(default_factory=list)
    faces: list[m.FacePosition] = field(default_factory=list)
    targets: list[m.RadarTargets] = field(default_factory=list)
    events: list[m.PersonEvent] = field(default_factory=list)
    states: list[m.ControllerState] = field(default_factory=list)


def run(name: str, seconds: float, folder: Path) -> Record:
    """The robot on scenario `name` for `seconds` once it is up; everything recorded."""
    config = folder / f"{name}.toml"
    text = '[audio_player]\nbackend = "null"\n'
    if name in LD2450_SCENARIOS:
        text += '[radar_bridge]\nsim_model = "LD2450"\n'
    config.write_text(text)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--scenario", name, "--listen",
                               endpoint, "--config", str(config), "--eye-port",
                               str(free_port()), "--dashboard-port", str(free_port()),
                               "--status-period", "1"), f"up-{name}", folder)
    rec = Record()
    try:
        n = len([e for e in available_services() if not e.on_request])
        up.wait_for_output(f"nodes {n}/{n}", 180)
        probe = Node("bench-probe", connect=[endpoint], probe=True)
        try:
            truth = Collector[m.SimWorld](probe, keys.SIM_WORLD)
            faces = Collector[m.FacePosition](probe, keys.FACE, camera="front")
            targets = Collector[m.RadarTargets](probe, keys.RADAR_TARGETS, device="*")
            events = Collector[m.PersonEvent](probe, keys.PEOPLE_EVENTS)
            states = Collector[m.ControllerState](probe, keys.CONTROLLER_STATE)
            time.sleep(seconds)
            rec = Record(truth.messages, faces.messages, targets.messages, events.messages,
                         states.messages)
        finally:
            probe.close()
    finally:
        up.stop(30)
    return rec


def truth_at(rec: Record, stamp_ns: int) -> m.SimWorld | None:
    """The truth sample nearest in time (within 0.2 s)."""
    best = min(rec.truth, key=lambda w: abs(w.stamp_ns - stamp_ns), default=None)
    return best if best is not None and abs(best.stamp_ns - stamp_ns) < 200_000_000 else None


def face_errors(rec: Record) -> tuple[list[float], list[float]]:
    """Distance error (% of the true depth) and bearing error (degrees) of every face."""
    dist, bearing = [], []
    for face in rec.faces:
        world = truth_at(rec, face.stamp_ns)
        if world is None or not world.people:
            continue
        b = math.atan2(face.point.y, face.point.x)
        person = min(world.people, key=lambda p: abs(p.bearing_rad - b))
        depth = person.position.x
        dist.append(abs(face.point.x - depth) / depth * 100.0)
        bearing.append(abs(math.degrees(b - person.bearing_rad)))
    return dist, bearing


def target_errors(rec: Record) -> list[float]:
    """Each LD2450 target's distance (m) from the nearest true person or clutter."""
    out = []
    for msg in rec.targets:
        world = truth_at(rec, msg.stamp_ns)
        if world is None:
            continue
        things = [(p.position.x, p.position.y) for p in world.people] + \
            [(c.position.x, c.position.y) for c in world.clutter]
        for t in msg.targets:
            if things:
                out.append(min(math.hypot(t.position.x - x, t.position.y - y)
                               for x, y in things))
    return out


def crossings(rec: Record) -> tuple[list[int], list[int]]:
    """Stamps where someone comes within range and where the last one leaves it (truth;
    leaving needs 0.1 m past the range, so a person standing on it counts once)."""
    enter, leave = [], []
    inside = False
    for world in rec.truth:
        limit = RANGE_M + (0.1 if inside else 0.0)
        now = any(p.in_radar and p.distance_m < limit for p in world.people)
        if now and not inside:
            enter.append(world.stamp_ns)
        if inside and not now:
            leave.append(world.stamp_ns)
        inside = now
    return enter, leave


def after(stamps: list[int], since: int, limit_s: float = 30.0) -> float | None:
    """Seconds from `since` to the first stamp after it (within `limit_s`)."""
    later = [s for s in stamps if since <= s <= since + limit_s * 1e9]
    return (min(later) - since) / 1e9 if later else None


def nearest(stamps: list[int], since: int, limit_s: float = 10.0) -> float | None:
    """Seconds from `since` to the nearest stamp within `limit_s` either way (negative:
    before it; the camera sees a visitor from 4 m, before they are within range)."""
    near = [s for s in stamps if abs(s - since) <= limit_s * 1e9]
    return (min(near, key=lambda s: abs(s - since)) - since) / 1e9 if near else None


def sound_starts(states: list[m.ControllerState], sound: str) -> list[int]:
    out, prev = [], None
    for s in states:
        if s.sound == sound and prev != sound:
            out.append(s.stamp_ns)
        prev = s.sound
    return out


def med(values: list[float | None]) -> str:
    got = [v for v in values if v is not None]
    return f"{statistics.median(got):.1f}" if got else "-"


def spread(values: list[float], unit: str) -> str:
    if not values:
        return "-"
    return f"{statistics.median(values):.1f} / {percentile(values, 0.95):.1f} {unit}"


def row(name: str, rec: Record) -> list[str]:
    dist, bearing = face_errors(rec)
    radar = target_errors(rec)
    enter, leave = crossings(rec)
    arrived = [e.stamp_ns for e in rec.events if e.kind == "ARRIVED"]
    left = [e.stamp_ns for e in rec.events if e.kind == "LEFT"]
    farewells = sound_starts(rec.states, "farewell")
    changes: dict[int, int] = {}
    for e in rec.events:
        if e.kind == "ENGAGEMENT_CHANGED":
            changes[e.person_id] = changes.get(e.person_id, 0) + 1
    return [name, str(len(rec.faces)), spread(dist, "%"), spread(bearing, "deg"),
            spread(radar, "m") if radar else "-",
            med([nearest(arrived, s) for s in enter]),
            med([after(left, s) for s in leave]), med([after(farewells, s) for s in leave]),
            f"{len(sound_starts(rec.states, 'greeting'))} / {len(enter)}",
            med([float(n) for n in changes.values()])]


HEAD = ["scenario", "faces", "face distance err (median / p95)", "face bearing err",
        "radar target err", "in range -> ARRIVED s", "left -> LEFT s", "left -> farewell s",
        "greetings / visits", "engagement changes per person"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", action="append", choices=scenarios.builtin_names())
    parser.add_argument("--laps", type=float, default=1.5,
                        help="how long a looping scenario runs, in its own lengths (one that "
                        "runs once: to its end and 15 s more; at most 240 s)")
    args = parser.parse_args(argv)
    chosen = args.scenario or list(DEFAULT)
    rows = []
    with tempfile.TemporaryDirectory(prefix="buddybot-scenarios-") as tmp:
        for name in chosen:
            spec = scenarios.load(name).spec
            seconds = min(MAX_S, max(30.0, spec.length_s * args.laps) if spec.loop
                          else spec.length_s + 15.0)
            rec = run(name, seconds, Path(tmp))
            rows.append(row(name, rec))
            print(f"{name}: {seconds:.0f} s, {len(rec.truth)} truth samples", flush=True)
    widths = [max(len(r[i]) for r in [HEAD, *rows]) for i in range(len(HEAD))]
    print()
    for r in [HEAD, ["-" * w for w in widths], *rows]:
        print("| " + " | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
