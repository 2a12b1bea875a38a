"""The presence service (`buddybot run radar-presence`) as a real process through a
real router, fed by the real radar-bridge reading simulated LD2410s on real ptys, or
by frames published straight to it: silence, restarts, malformed and flooding
frames, implausible stamps, a parameter changed while it runs, and LD2450 target
reports beside LD2410 frames, through the zones."""

from __future__ import annotations

import random
import subprocess
import threading
from collections.abc import Callable
from pathlib import Path

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.radar.sim import PtySensor
from buddybot.radar.sim_scene import NOBODY, Target
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until
from tests.radar.rig import radar_target, standing

pytestmark = pytest.mark.integration

IN, OUT = m.PresenceState.IN_RANGE, m.PresenceState.OUT_OF_RANGE
Spawn = Callable[..., Process]


def test_silent_sensor_is_reported_not_taken_for_nobody(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    sensor = sensors(standing)
    presence = Collector(probe, keys.PRESENCE)
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    spawn("radar-bridge", "--sensor", sensor.path)
    spawn("radar-presence", "--absence-hold-s", "0.5", "--stale-after-s", "1.0")
    presence.wait_for(lambda v: v.presence_state == IN, 30, "IN_RANGE")
    sensor.unplug()
    silent = pdiag.wait_for(lambda d: d.level == "ERROR", 20, "presence reporting silence")
    assert "0/0" in silent.message
    # Several absence holds later (diagnostics come every 2 s), still IN_RANGE.
    pdiag.wait_for(lambda d: d.stamp_ns > silent.stamp_ns + 3e9, 20, "time passing")
    assert [v.presence_state for v in presence.messages] == [IN]
    sensor.replug()
    pdiag.wait_for(lambda d: d.level == "OK" and d.stamp_ns > silent.stamp_ns, 30, "sensor back")


class Switch:
    """A person at 1 m while `here` is set, else nobody."""

    def __init__(self) -> None:
        self.here = threading.Event()

    def __call__(self, t: float, rng: random.Random) -> Target:
        return standing(t, rng) if self.here.is_set() else NOBODY


def test_restarted_presence_contradicts_a_stale_in_range(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """Killed while IN_RANGE, restarted after the visitor left: it says OUT_OF_RANGE."""
    switch = Switch()
    switch.here.set()
    sensor = sensors(switch)
    presence = Collector(probe, keys.PRESENCE)
    spawn("radar-bridge", "--sensor", sensor.path)
    first = spawn("radar-presence", "--absence-hold-s", "0.5")
    presence.wait_for(lambda v: v.presence_state == IN, 30, "IN_RANGE")
    first.kill()
    switch.here.clear()
    spawn("radar-presence", "--absence-hold-s", "0.5")
    presence.wait_for(lambda v: v.presence_state == OUT, 30, "OUT_OF_RANGE from the new one")
    assert [v.presence_state for v in presence.messages] == [IN, OUT]


def test_presence_survives_malformed_frames(spawn: Spawn, probe: Node) -> None:
    presence = Collector(probe, keys.PRESENCE)
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    service = spawn("radar-presence")
    pdiag.wait_for(timeout=30, what="presence up")
    raw = probe.raw_publisher(probe.key(keys.RADAR_FRAMES, device="7"),
                              keys.RADAR_FRAMES.encoding)
    good = probe.publisher(keys.RADAR_FRAMES, device="7")
    other = probe.publisher(keys.RADAR_FRAMES, device="8")  # a second bridge: nobody there
    empty = m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.NO_TARGET,
                                    movement_distance=0, movement_energy=0,
                                    stationary_distance=0, stationary_energy=0,
                                    detection_distance=0)
    near = m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.MOVING,
                                   movement_distance=120, movement_energy=50,
                                   stationary_distance=0, stationary_energy=0,
                                   detection_distance=120)
    over = msgspec.json.encode(msgspec.to_builtins(near)).replace(b'"movement_energy":50',
                                                                    b'"movement_energy":300')

    def send() -> bool:
        raw.put(b"\x00\xff not json")
        raw.put(b'{"stamp_ns":1,"device_id":7,"sensors":[' + over + b"]}")
        other.put(m.LD2410TargetDataFrameArray(stamp_ns=m.now_ns(), device_id=8,
                                               sensors=[empty]))
        good.put(m.LD2410TargetDataFrameArray(stamp_ns=m.now_ns(), device_id=7, sensors=[near]))
        return any(v.presence_state == IN for v in presence.messages)

    retry_until(send, 30, 0.2, "IN_RANGE from the valid frame")
    d = pdiag.wait_for(lambda d: int(d.values.get("malformed", 0)) >= 2
                       and d.values.get("sensors") == 2, 20, "malformed counted, 2 devices")
    assert d.level in ("OK", "WARN")
    assert [v.distance_m for v in presence.messages][:1] == [1.2]
    raw.close()
    assert service.alive()


def test_a_flood_of_fake_radar_ids_is_bounded_and_the_real_sensor_still_counts(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """Floods of 28k invented sensors saying "nobody" while a real one sees a person:
    presence stays IN_RANGE, the table and the diagnostics stay small, memory
    stops growing."""
    import psutil

    sensor = sensors(standing)
    presence = Collector(probe, keys.PRESENCE)
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    spawn("radar-bridge", "--sensor", sensor.path)
    service = spawn("radar-presence", "--absence-hold-s", "1.0")
    presence.wait_for(lambda v: v.presence_state == IN, 30, "IN_RANGE")
    pdiag.wait_for(lambda d: d.level == "OK", 30, "presence OK")
    nobody = m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.NO_TARGET,
                                     movement_distance=0, movement_energy=0,
                                     stationary_distance=0, stationary_energy=0,
                                     detection_distance=0)
    pubs = [probe.publisher(keys.RADAR_FRAMES, device=f"evil{d}") for d in range(4)]
    rss: list[int] = []
    next_id = 0

    def evicted_now() -> int:
        return int(pdiag.messages[-1].values.get("evicted_sensors") or 0)

    def publish_batch() -> None:  # 2,800 new ids in 280 messages
        nonlocal next_id
        for batch in range(280):
            pubs[batch % 4].put(m.LD2410TargetDataFrameArray(
                stamp_ns=m.now_ns(), device_id=0,
                sensors=[msgspec.structs.replace(nobody, radar_id=next_id + i)
                         for i in range(10)]))
            next_id += 10

    for flood in range(4):  # each flood: new ids until 10,000 of them were taken
        target = evicted_now() + 10_000
        retry_until(lambda t=target: publish_batch() or evicted_now() >= t, 120, 0.5,
                    f"flood {flood} taken")  # stream samples may be dropped: send more
        # Processed (or dropped) once the count stops moving between two reports.
        seen = [pdiag.messages[-1]]
        done = pdiag.wait_for(
            lambda d, seen=seen: d.stamp_ns > seen[-1].stamp_ns and (
                d.values.get("evicted_sensors") == seen[-1].values.get("evicted_sensors")
                or bool(seen.append(d))), 60, f"flood {flood} processed")
        rss.append(psutil.Process(service.pid).memory_info().rss)
    evicted = int(done.values["evicted_sensors"])  # type: ignore[arg-type]
    print(f"flood: {evicted} invented sensors evicted, dropped "
          f"{done.values.get('dropped_frames')} messages, "
          f"established dropped {done.values.get('dropped_established_frames')}")
    # Several absence holds after the last flood, the real sensor still counts.
    pdiag.wait_for(lambda d: d.stamp_ns > done.stamp_ns + 3e9, 30, "time passing")
    assert [v.presence_state for v in presence.messages] == [IN], presence.messages
    worst = max(len(msgspec.json.encode(d)) for d in pdiag.messages)
    assert worst < 2000, worst  # one entry per invented sensor would be ~474 KB
    last = pdiag.messages[-1]
    assert int(last.values["sensors"]) <= 16  # type: ignore[arg-type]
    stale = str(last.values.get("stale")).split(" (+")[0].split(", ")
    assert "0/0" not in stale, stale  # the real sensor is not "silent"
    # Memory: the first floods fill transport buffers and the delivery queue to their
    # high-water mark; later floods of new ids must not add to it (an unbounded
    # table grows by hundreds of bytes per id: > 20 MB for two floods).
    print(f"RSS after each flood: {[round(r / 1e6, 1) for r in rss]} MB")
    assert rss[3] - rss[1] < 10e6, rss
    assert service.alive()


def test_ids_left_by_a_flood_are_not_reported_as_silent_sensors(
        sensors: Callable[..., PtySensor], spawn: Spawn, probe: Node) -> None:
    """After a flood the table holds 15 invented ids next to the real sensor: they
    read "15 of 16 sensor(s) silent" for minutes before; now they are forgotten
    once silent and the real sensor is OK again."""
    sensor = sensors(standing)
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    spawn("radar-bridge", "--sensor", sensor.path)
    spawn("radar-presence")
    pdiag.wait_for(lambda d: d.level == "OK", 30, "presence OK")
    nobody = m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.NO_TARGET,
                                     movement_distance=0, movement_energy=0,
                                     stationary_distance=0, stationary_energy=0,
                                     detection_distance=0)
    evil = probe.publisher(keys.RADAR_FRAMES, device="evil")
    sent = 0

    def flood() -> bool:  # new ids each time: each is heard once, as in a flood
        nonlocal sent
        for _ in range(4):
            evil.put(m.LD2410TargetDataFrameArray(
                stamp_ns=m.now_ns(), device_id=0,
                sensors=[msgspec.structs.replace(nobody, radar_id=sent + i) for i in range(16)]))
            sent += 16
        return any(int(d.values.get("evicted_sensors") or 0) > 0 for d in pdiag.messages)

    retry_until(flood, 30, 0.2, "the invented ids taken")
    flooded = pdiag.messages[-1].stamp_ns
    back = pdiag.wait_for(lambda d: d.stamp_ns > flooded and d.level == "OK"
                          and d.values.get("sensors") == 1, 30, "the invented ids forgotten")
    assert back.values.get("stale_count") == 0 and int(back.values["evicted_sensors"]) > 0


def _near_and_empty() -> tuple[m.LD2410TargetDataFrame, m.LD2410TargetDataFrame]:
    """A moving target at 1.2 m, and the same sensor seeing nobody."""
    near = m.LD2410TargetDataFrame(radar_id=0, target_state=m.TargetState.MOVING,
                                   movement_distance=120, movement_energy=50,
                                   stationary_distance=0, stationary_energy=0,
                                   detection_distance=120)
    empty = msgspec.structs.replace(near, target_state=m.TargetState.NO_TARGET,
                                    movement_distance=0, movement_energy=0,
                                    detection_distance=0)
    return near, empty


def test_presence_never_publishes_an_implausible_stamp(spawn: Spawn, probe: Node) -> None:
    """One frame stamped 2**63-1 (and one 15 s ahead) must not become the stamp
    of every later verdict."""
    presence = Collector(probe, keys.PRESENCE)
    pdiag = Collector(probe, keys.DIAGNOSTICS, node="radar-presence")
    service = spawn("radar-presence", "--absence-hold-s", "0.5")
    pdiag.wait_for(timeout=30, what="presence up")
    pub = probe.publisher(keys.RADAR_FRAMES, device="7")
    near, empty = _near_and_empty()
    start = m.now_ns()

    def frame(stamp: int, f: m.LD2410TargetDataFrame) -> m.LD2410TargetDataFrameArray:
        return m.LD2410TargetDataFrameArray(stamp_ns=stamp, device_id=7, sensors=[f])

    def send_poisoned() -> bool:
        pub.put(frame(2**63 - 1, near))
        pub.put(frame(m.now_ns() + 15 * 10**9, near))
        return bool(presence.messages)

    retry_until(send_poisoned, 30, 0.2, "IN_RANGE from the poisoned frames")
    retry_until(lambda: pub.put(frame(m.now_ns(), empty)) or any(
        v.presence_state == OUT for v in presence.messages), 30, 0.1, "OUT_OF_RANGE")
    retry_until(lambda: pub.put(frame(m.now_ns(), near)) or [
        v.presence_state for v in presence.messages].count(IN) >= 2, 30, 0.1, "IN_RANGE again")
    end = m.now_ns()
    stamps = [v.stamp_ns for v in presence.messages]
    assert all(start - 10**9 <= s <= end + 10**9 for s in stamps), stamps
    # Counted by the runtime (which replaces such stamps before any handler)
    # or, behind it, by radar-presence itself.
    d = pdiag.wait_for(lambda d: int(d.values.get("implausible_stamps") or 0)
                       + int(d.values.get("stamps replaced") or 0) >= 2, 20,
                       "implausible stamps counted")
    assert d.level in ("OK", "WARN", "ERROR")
    assert service.alive()


def test_presence_service_itself_replaces_implausible_stamps(
        probe: Node, node_factory: Callable[..., Node]) -> None:
    """The service's own defence, whatever the runtime does before it: frames
    handed straight to its handler with stamps 2**63-1 and now+15 s; every
    verdict it publishes (through the router) is stamped plausibly."""
    from buddybot.radar.presence_service import PresenceService
    from buddybot.radar.settings import RadarPresenceSettings

    # Raw samples: a typed subscriber's runtime would itself replace a bad stamp.
    raw: list[bytes] = []
    lock = threading.Lock()

    def on_sample(_key: str, payload: bytes, _encoding: str) -> None:
        with lock:
            raw.append(payload)

    sub = probe.subscribe_raw(probe.key(keys.PRESENCE), on_sample)
    node = node_factory("radar-presence-inproc")
    service = PresenceService(node, RadarPresenceSettings(absence_hold_s=0.2))
    key = node.key(keys.RADAR_FRAMES, device="5")
    near, empty = _near_and_empty()
    start = m.now_ns()
    for stamp in (2**63 - 1, m.now_ns() + 15 * 10**9):
        service.on_frames(m.LD2410TargetDataFrameArray(stamp_ns=stamp, device_id=5,
                                                       sensors=[near]), key)
    service.on_frames(m.LD2410TargetDataFrameArray(stamp_ns=2**63 - 1, device_id=5,
                                                   sensors=[empty]), key)

    def absence_over() -> bool:
        service.tick()
        return bool(service.tracker.presence == OUT)

    retry_until(absence_over, 10, 0.05, "OUT_OF_RANGE after the hold")
    retry_until(lambda: len(raw) >= 2, 20, what="two verdicts")
    end = m.now_ns()
    with lock:
        got = [keys.PRESENCE.codec.decode(b, m.PresenceDetection) for b in raw]
    sub.close()
    assert [v.presence_state for v in got] == [IN, OUT]
    assert all(start - 10**9 <= v.stamp_ns <= end + 10**9 for v in got), got
    assert service.implausible_stamps >= 3


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_range_m_set_live_moves_the_decision(sensors: Callable[..., PtySensor], spawn: Spawn,
                                             probe: Node, endpoint: str) -> None:
    """`buddybot param set radar-presence range_m ...` moves the IN/OUT decision while it
    runs: one person standing 1.00 m away, `range_m` changed twice, no restart in between
    (the same process, checked by its pid and its node instance)."""
    sensor = sensors(standing)
    presence = Collector[m.PresenceDetection](probe, keys.PRESENCE)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="radar-presence")
    spawn("radar-bridge", "--sensor", sensor.path)
    service = spawn("radar-presence", "--range-m", "0.5", "--absence-hold-s", "0.3")
    pid = service.pid
    # 1.00 m is beyond 0.5 m: nobody in range.
    assert presence.wait_for(timeout=30, what="first verdict").presence_state == OUT

    result = param(endpoint, "set", "radar-presence", "range_m", "1.5")
    assert result.returncode == 0, result.stderr
    assert "radar_presence.range_m = 1.5 (applied)" in result.stdout
    entered = presence.wait_for(lambda v: v.presence_state == IN, 15, "IN_RANGE after the set")
    assert entered.distance_m == pytest.approx(1.0, abs=0.01)

    presence.clear()
    result = param(endpoint, "set", "radar-presence", "range_m", "0.5")
    assert result.returncode == 0, result.stderr
    presence.wait_for(lambda v: v.presence_state == OUT, 15, "OUT_OF_RANGE after the set")

    # One process all along, which says what changed, in its log and its diagnostics.
    assert service.alive() and service.pid == pid
    service.wait_for_output("parameters changed: range_m=0.5")
    changed = diag.wait_for(lambda d: d.values.get("params_changed") == 2, 15,
                            "params_changed in diagnostics")
    assert changed.values["last_param_change"] == "range_m=0.5"


class Scene:
    """A bridge with an LD2410 (radar 0, on radar/0/frames) and an LD2450 (radar 1,
    on radar/0/targets), each reporting what `frame` and `targets` say, at 10 Hz."""

    def __init__(self, probe: Node) -> None:
        near, empty = _near_and_empty()
        self.near, self.empty = near, empty
        self.frame = empty
        self.targets: list[m.RadarTarget] = []
        self._frames = probe.publisher(keys.RADAR_FRAMES, device="0")
        self._targets = probe.publisher(keys.RADAR_TARGETS, device="0")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="scene", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(0.1):
            stamp = m.now_ns()
            self._frames.put(m.LD2410TargetDataFrameArray(stamp_ns=stamp, device_id=0,
                                                          sensors=[self.frame]))
            self._targets.put(m.RadarTargets(stamp_ns=stamp, device_id=0, radar_id=1,
                                             targets=list(self.targets)))

    def __enter__(self) -> Scene:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)


def test_presence_from_ld2450_targets_and_ld2410_frames_with_an_ignore_zone(
        tmp_path: Path, spawn: Spawn, probe: Node, endpoint: str) -> None:
    """Both models on one bridge: a TV in the doorway zone never makes presence, a
    person elsewhere does (LD2450 alone, then the LD2410 alone); malformed target
    reports are counted and change nothing; zones removed live, the TV counts."""
    config = tmp_path / "robot.toml"
    config.write_text('[radar_presence]\nabsence_hold_s = 0.5\nzones = [{name = "doorway", '
                      'mode = "ignore", x = [2.0, 3.0], y = [-1.0, 0.0]}]\n')
    presence = Collector[m.PresenceDetection](probe, keys.PRESENCE)
    pdiag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="radar-presence")
    service = spawn("radar-presence", "--config", str(config), "--range-m", "3.0")
    wanted = {keys.RADAR_FRAMES.wildcard(), keys.RADAR_TARGETS.wildcard()}
    retry_until(lambda: any(i.node == "radar-presence" and wanted <= set(i.subscriptions)
                            for i in probe.node_infos(1.0)), 30, 0.2, "both subscriptions")

    raw = probe.raw_publisher(probe.key(keys.RADAR_TARGETS, device="0"),
                              keys.RADAR_TARGETS.encoding)
    good = msgspec.to_builtins(m.RadarTargets(stamp_ns=m.now_ns(), device_id=0, radar_id=1,
                                              targets=[radar_target(1.0, 0.0)]))
    bad_slot = {**good, "targets": [{**good["targets"][0], "slot": 9}]}
    too_many = {**good, "targets": good["targets"] * 9}
    malformed = [b"\x00\xff not json", b'{"stamp_ns":1,"device_id":0}',
                 msgspec.json.encode(bad_slot), msgspec.json.encode(too_many)]
    for payload in malformed:
        raw.put(payload)
    pdiag.wait_for(lambda d: int(d.values.get("malformed") or 0) >= len(malformed), 20,
                   "malformed target reports counted")
    raw.close()

    tv = radar_target(2.5, -0.5, 0.3)  # 2.55 m away: within range, inside the doorway zone
    with Scene(probe) as scene:
        scene.targets = [tv]
        first = presence.wait_for(timeout=30, what="first verdict")
        assert first.presence_state == OUT, first  # the TV alone is nobody
        pdiag.wait_for(lambda d: int(d.values.get("targets_in_ignore_zones") or 0) >= 5, 20,
                       "targets in the doorway counted")

        scene.targets = [tv, radar_target(1.0, 0.3, 0.0, slot=1)]  # someone standing
        entered = presence.wait_for(lambda v: v.presence_state == IN, 20, "IN_RANGE (LD2450)")
        assert entered.target_state == m.PresenceTarget.STANDING
        assert entered.distance_m == pytest.approx(1.044, abs=0.001)

        scene.targets = [tv]
        presence.wait_for(lambda v: v.presence_state == OUT and v.stamp_ns > entered.stamp_ns,
                          20, "OUT_OF_RANGE: only the TV left")

        presence.clear()
        scene.frame = scene.near  # the LD2410 sees someone the LD2450 does not
        from_ld2410 = presence.wait_for(lambda v: v.presence_state == IN, 20,
                                        "IN_RANGE (LD2410)")
        assert from_ld2410.distance_m == pytest.approx(1.2)
        scene.frame = scene.empty
        presence.wait_for(lambda v: v.presence_state == OUT, 20, "OUT_OF_RANGE again")
        d = pdiag.wait_for(lambda d: d.values.get("sensors") == 2 and d.level == "OK", 20,
                           "both sensors fresh")
        assert int(d.values.get("targets_outside_detect_zones") or 0) == 0

        result = param(endpoint, "set", "radar-presence", "zones", "[]")
        assert result.returncode == 0, result.stderr
        tv_counts = presence.wait_for(lambda v: v.presence_state == IN
                                      and v.distance_m > 2.5, 20, "IN_RANGE: the TV counts")
        assert tv_counts.target_state == m.PresenceTarget.MOVING  # 0.3 m/s
    assert all(v.presence_state in (IN, OUT) for v in presence.messages)
    assert service.alive()
