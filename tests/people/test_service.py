"""The people service: the pure mapping between messages and the model (faces to
distance and direction, persons and events to messages), the adapter on a fake node
(events in order, the state only on change), and `buddybot run people` as a process
behind a real router (marked `integration`): a visit's events with the sensor
stamps, the latched state for a late subscriber, garbage counted, a live parameter."""

from __future__ import annotations

import math
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.people.model import (
    Arrived,
    Engagement,
    EngagementChanged,
    FaceSeen,
    Left,
    Person,
    PersonEvent,
    RadarSeen,
    RangeSeen,
    Sensor,
    Tick,
    ZoneChanged,
)
from buddybot.people.service import (
    PeopleService,
    event_messages,
    face_seen,
    person_message,
    radar_seen,
    ranges_seen,
    state_message,
    state_stamp,
    targets_seen,
)
from buddybot.people.settings import PeopleSettings
from buddybot.people.zones import Zone
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Collector,
    FakeDiagnostics,
    Process,
    RecordingPublisher,
    buddybot_argv,
    retry_until,
)

S = 1_000_000_000
T0 = 1_700_000_000 * S
Spawn = Callable[..., Process]


# --- messages -> inputs ----------------------------------------------------------------


def _face(x: float, y: float, z: float, stamp: int = T0) -> m.FacePosition:
    return m.FacePosition(stamp_ns=stamp, frame_id="front", point=m.Point(x=x, y=y, z=z),
                          confidence=0.9)


def test_a_face_straight_ahead_is_its_distance_at_yaw_and_pitch_zero() -> None:
    assert face_seen(_face(1.5, 0.0, 0.0)) == FaceSeen(T0, 1.5, 0.0, 0.0)


def test_a_face_left_and_up_has_positive_yaw_and_pitch() -> None:
    face = face_seen(_face(1.0, 1.0, math.sqrt(2.0)))
    assert face.distance_m == pytest.approx(2.0)
    assert face.yaw_rad == pytest.approx(math.pi / 4)
    assert face.pitch_rad == pytest.approx(math.pi / 4)
    right_down = face_seen(_face(1.0, -1.0, -1.0))
    assert right_down.yaw_rad < 0 and right_down.pitch_rad < 0


def test_a_face_farther_than_a_person_message_carries_is_refused() -> None:
    with pytest.raises(ValueError, match="m away"):
        face_seen(_face(900.0, 900.0, 0.0))


def test_presence_is_in_range_with_its_distance_and_stamp() -> None:
    def presence(state: m.PresenceState) -> m.PresenceDetection:
        return m.PresenceDetection(stamp_ns=T0, target_state=m.PresenceTarget.STANDING,
                                   presence_state=state, distance_m=2.5)

    assert radar_seen(presence(m.PresenceState.IN_RANGE)) == RadarSeen(T0, True, 2.5)
    assert radar_seen(presence(m.PresenceState.OUT_OF_RANGE)) == RadarSeen(T0, False, 2.5)


def test_each_ld2410_frame_is_its_nearest_target_or_nobody() -> None:
    def frame(radar_id: int, state: int, detection: int, moving: int = 0,
              still: int = 0) -> m.LD2410TargetDataFrame:
        return m.LD2410TargetDataFrame(
            radar_id=radar_id, target_state=m.TargetState(state), movement_distance=moving,
            movement_energy=50, stationary_distance=still, stationary_energy=50,
            detection_distance=detection)

    msg = m.LD2410TargetDataFrameArray(stamp_ns=T0, device_id=3, sensors=[
        frame(0, 1, 170), frame(1, 0, 0), frame(2, 2, 0, moving=90, still=140),
        frame(3, 5, 120)])  # 5: the sensor measures its background noise
    assert ranges_seen(msg) == [RangeSeen(T0, (3, 0), 1.7), RangeSeen(T0, (3, 1), None),
                                RangeSeen(T0, (3, 2), 1.4), RangeSeen(T0, (3, 3), None)]


# --- model -> messages -----------------------------------------------------------------


def _person(**fields: Any) -> Person:
    base: dict[str, Any] = dict(
        id=1, distance_m=1.0, zone=Zone.PERSONAL, seen_by=Sensor.BOTH, zone_since_ns=T0,
        arrived_ns=T0, engagement=Engagement.NONE, engagement_since_ns=T0)
    return Person(**(base | fields))


@pytest.mark.parametrize("sensor, name", [
    (Sensor.NONE, "NONE"), (Sensor.RADAR, "RADAR"), (Sensor.CAMERA, "CAMERA"),
    (Sensor.BOTH, "BOTH")])
def test_every_sensor_flag_has_its_name(sensor: Sensor, name: str) -> None:
    assert person_message(_person(seen_by=sensor)).seen_by == name


def test_a_person_message_carries_every_field_and_decodes() -> None:
    p = _person(id=7, distance_m=2.25, zone=Zone.SOCIAL, seen_by=Sensor.CAMERA,
                zone_since_ns=T0 + 2, arrived_ns=T0 + 1, engagement=Engagement.DISENGAGING,
                engagement_since_ns=T0 + 3, yaw_rad=0.25, pitch_rad=-0.5, name="Ada")
    msg = person_message(p)
    assert (msg.id, msg.distance_m, msg.zone, msg.seen_by) == (7, 2.25, "SOCIAL", "CAMERA")
    assert (msg.arrived_ns, msg.zone_since_ns, msg.engagement_since_ns) == (T0 + 1, T0 + 2,
                                                                            T0 + 3)
    assert (msg.engagement, msg.yaw_rad, msg.pitch_rad, msg.name) == ("DISENGAGING", 0.25,
                                                                      -0.5, "Ada")
    assert msg.bearing_rad is None
    assert person_message(_person(bearing_rad=0.5)).bearing_rad == 0.5
    state = state_message((p,), T0 + 3)
    wire = keys.PEOPLE_STATE.codec.encode(state)
    assert keys.PEOPLE_STATE.codec.decode(wire, m.PeopleState) == state


def test_every_zone_and_engagement_has_a_contract_value() -> None:
    for zone in Zone:
        for engagement in Engagement:
            msg = person_message(_person(zone=zone, engagement=engagement))
            assert (msg.zone, msg.engagement) == (zone.name, engagement.name)


def test_events_carry_the_zone_and_engagement_right_after_them() -> None:
    """One step's zone change and engagement change each see the other's result."""
    arrived = _person(id=2, zone=Zone.PUBLIC, distance_m=4.0)
    left = _person(id=2, zone=Zone.PERSONAL, engagement=Engagement.GONE, seen_by=Sensor.NONE)
    events: list[PersonEvent] = [
        Arrived(2, T0, arrived),
        ZoneChanged(2, T0 + 1, Zone.PUBLIC, Zone.SOCIAL, 3.0),
        EngagementChanged(2, T0 + 1, Engagement.NONE, Engagement.ENGAGING),
        ZoneChanged(2, T0 + 2, Zone.SOCIAL, Zone.PERSONAL, 1.0),
        EngagementChanged(2, T0 + 3, Engagement.ENGAGING, Engagement.GONE),
        Left(2, T0 + 3, left),
    ]
    got = [(e.stamp_ns - T0, e.person_id, e.kind, e.zone, e.engagement)
           for e in event_messages(events, ())]
    assert got == [
        (0, 2, "ARRIVED", "PUBLIC", "NONE"),
        (1, 2, "ZONE_CHANGED", "SOCIAL", "NONE"),
        (1, 2, "ENGAGEMENT_CHANGED", "SOCIAL", "ENGAGING"),
        (2, 2, "ZONE_CHANGED", "PERSONAL", "ENGAGING"),
        (3, 2, "ENGAGEMENT_CHANGED", "PERSONAL", "GONE"),
        (3, 2, "LEFT", "PERSONAL", "GONE"),
    ]


def test_a_step_starts_from_the_state_before_it() -> None:
    before = (_person(id=4, zone=Zone.SOCIAL, engagement=Engagement.ENGAGED),)
    [msg] = event_messages([ZoneChanged(4, T0, Zone.SOCIAL, Zone.PUBLIC, 4.0)], before)
    assert (msg.kind, msg.zone, msg.engagement) == ("ZONE_CHANGED", "PUBLIC", "ENGAGED")


def test_the_state_stamp_is_the_newest_data_that_changed_it() -> None:
    timer = EngagementChanged(1, T0 + 5, Engagement.ENGAGING, Engagement.ENGAGED)
    assert state_stamp(Tick(T0 + 9), []) == T0 + 9
    assert state_stamp(Tick(T0 + 9), [timer]) == T0 + 5
    assert state_stamp(FaceSeen(T0 + 7, 1.0, 0.0, 0.0), [timer]) == T0 + 7
    assert state_stamp(RadarSeen(T0 + 3, True, 1.0), [timer]) == T0 + 5


# --- the adapter on a fake node ------------------------------------------------------------


class FakeNode:
    """What `PeopleService` uses of a Node: publishers that record, no Zenoh."""

    def __init__(self) -> None:
        self.out: list[Any] = []
        self.diagnostics = FakeDiagnostics()

    def publisher(self, _topic: keys.Topic, /, **_params: str) -> RecordingPublisher:
        return RecordingPublisher(self.out)


def _service(**settings: Any) -> tuple[PeopleService, FakeNode]:
    node = FakeNode()
    service = PeopleService(node, PeopleSettings(**settings))  # type: ignore[arg-type]
    return service, node


def test_events_go_out_in_order_and_the_state_only_on_change() -> None:
    service, node = _service(engage_dwell_s=0.3)
    presence = m.PresenceDetection(stamp_ns=T0, target_state=m.PresenceTarget.STANDING,
                                   presence_state=m.PresenceState.IN_RANGE, distance_m=2.0)
    service._on_presence(presence, "radar/presence")
    service.step(Tick(T0 + S // 10))  # nothing changes: nothing published
    service._on_face(_face(1.0, 0.0, 0.0, T0 + S // 5), "camera/front/face")
    service.step(Tick(T0 + 6 * S // 10))  # the face (timeout 0.5 s) still counts
    kinds = [(type(x).__name__, getattr(x, "kind", None), x.stamp_ns - T0) for x in node.out]
    assert kinds == [
        ("PersonEvent", "ARRIVED", 0),
        ("PeopleState", None, 0),
        ("PersonEvent", "ZONE_CHANGED", S // 5),
        ("PersonEvent", "ENGAGEMENT_CHANGED", S // 5),
        ("PeopleState", None, S // 5),
        ("PersonEvent", "ENGAGEMENT_CHANGED", S // 2),
        ("PeopleState", None, S // 2),
    ]
    last = node.out[-1]
    assert [(p.id, p.zone, p.engagement, p.seen_by) for p in last.people] == [
        (1, "PERSONAL", "ENGAGED", "BOTH")]


def test_a_face_at_30_per_second_moves_the_state_10_times_a_second_and_news_is_not_held(
) -> None:
    clock = [0.0]
    node = FakeNode()
    service = PeopleService(node, PeopleSettings(engage_dwell_s=0.5),  # type: ignore[arg-type]
                            clock=lambda: clock[0])
    for frame in range(60):  # two seconds of a face coming nearer
        clock[0] = frame / 30
        stamp = T0 + frame * S // 30
        service._on_face(_face(2.0 - frame / 100, 0.0, 0.0, stamp), "camera/front/face")
        if frame % 2:  # the node's timer, every 50 ms or so
            service.step(Tick(stamp))
    states = [x for x in node.out if isinstance(x, m.PeopleState)]
    assert 15 <= len(states) <= 21
    engaged = next(s for s in states if s.people[0].engagement == "ENGAGED")
    assert engaged.stamp_ns == T0 + 15 * S // 30  # the frame that made it ENGAGED
    stamps = [s.stamp_ns for s in states]
    assert stamps == sorted(stamps)


def test_a_face_too_far_is_counted_and_dropped() -> None:
    service, node = _service()
    service._on_face(_face(900.0, 900.0, 0.0), "camera/front/face")
    assert node.out == [] and node.diagnostics.values == {"bad_faces": 1}


def test_a_live_setting_is_used_by_the_next_step() -> None:
    service, node = _service(engage_dwell_s=60.0)
    service._on_face(_face(1.0, 0.0, 0.0, T0), "camera/front/face")
    service.apply_settings(PeopleSettings(engage_dwell_s=0.1))
    service.step(Tick(T0 + S // 5))
    engaged = [x for x in node.out if getattr(x, "engagement", None) == "ENGAGED"]
    assert [e.stamp_ns for e in engaged] == [T0 + S // 10]


def radar_targets(stamp_ns: int, *points: tuple[float, float], device_id: int = 1,
                  radar_id: int = 0) -> m.RadarTargets:
    """An angle-radar report with targets at `points` (camera frame; sensor at the camera)."""
    return m.RadarTargets(stamp_ns=stamp_ns, device_id=device_id, radar_id=radar_id, targets=[
        m.RadarTarget(slot=i, x_m=-y, y_m=x, speed_mps=0.0, resolution_m=0.32,
                      position=m.Point(x=x, y=y, z=0.0), bearing_rad=math.atan2(y, x),
                      distance_m=math.hypot(x, y)) for i, (x, y) in enumerate(points)])


def test_a_radar_report_becomes_the_models_targets_in_the_camera_frame() -> None:
    seen = targets_seen(radar_targets(T0, (2.0, 0.5), (1.0, -1.0), device_id=3, radar_id=1))
    assert seen.stamp_ns == T0 and seen.sensor == (3, 1)
    assert [(t.x_m, t.y_m) for t in seen.targets] == [(2.0, 0.5), (1.0, -1.0)]


def test_radar_targets_make_persons_with_their_bearing() -> None:
    service, node = _service()
    service._on_targets(radar_targets(T0, (2.0, 0.5), (1.0, -1.0)), "radar/1/targets")
    state = node.out[-1]
    assert isinstance(state, m.PeopleState)
    assert [(p.id, p.seen_by) for p in state.people] == [(1, "RADAR"), (2, "RADAR")]
    assert state.people[1].bearing_rad == pytest.approx(math.atan2(0.5, 2.0))
    assert state.people[1].yaw_rad == state.people[1].bearing_rad

def test_a_face_name_names_the_person_and_a_forgotten_one_is_cleared_at_once() -> None:
    service, node = _service()
    service._on_face(_face(1.0, 0.0, 0.0, T0), "camera/front/face")
    name = m.FaceName(stamp_ns=T0 + 1, frame_id="camera", track=4, name="Ada", score=0.95,
                      votes=3)
    service._on_name(name, "identity/front/name")
    assert node.out[-1].people[0].name == "Ada"
    service._on_name(m.FaceName(stamp_ns=T0 + 2, frame_id="camera", track=4),
                     "identity/front/name")
    assert node.out[-1].people[0].name is None  # republished at once, without the name


def test_a_blank_face_name_is_counted_and_dropped() -> None:
    service, node = _service()
    service._on_name(m.FaceName(stamp_ns=T0, frame_id="camera", track=4, name=" "),
                     "identity/front/name")
    assert node.out == [] and node.diagnostics.values == {"bad_names": 1}


# --- the process -------------------------------------------------------------------------


def _config(tmp_path: Path, **fields: float) -> str:
    path = tmp_path / "people.toml"
    path.write_text("[people]\n" + "".join(f"{k} = {v}\n" for k, v in fields.items()))
    return str(path)


def _start(spawn: Spawn, probe: Node, tmp_path: Path, **fields: float) -> tuple[
        Process, Collector[m.PersonEvent], Collector[m.PeopleState]]:
    """The service with `fields` in its `[people]` table, up once its first (empty)
    state arrived."""
    events = Collector[m.PersonEvent](probe, keys.PEOPLE_EVENTS)
    state = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
    proc = spawn("people", "--config", _config(tmp_path, **fields))
    state.wait_for(lambda s: s.people == [], 30, "the first, empty, people/state")
    return proc, events, state


class Visitor:
    """Presence and faces as the radar and the face detector would publish them."""

    def __init__(self, probe: Node) -> None:
        self.presence_pub = probe.publisher(keys.PRESENCE)
        self.face_pub = probe.publisher(keys.FACE, camera="front")
        self.faces: list[int] = []

    def presence(self, in_range: bool, distance_m: float = 1.0) -> int:
        stamp = m.now_ns()
        state = m.PresenceState.IN_RANGE if in_range else m.PresenceState.OUT_OF_RANGE
        self.presence_pub.put(m.PresenceDetection(
            stamp_ns=stamp, target_state=m.PresenceTarget.STANDING, presence_state=state,
            distance_m=distance_m))
        return stamp

    def face(self, distance_m: float = 1.0) -> int:
        stamp = m.now_ns()
        self.face_pub.put(_face(distance_m, 0.0, 0.0, stamp))
        self.faces.append(stamp)
        return stamp


def _engaged(events: Collector[m.PersonEvent]) -> bool:
    return any(e.engagement == "ENGAGED" for e in events.messages)


@pytest.mark.integration
def test_a_visitor_arrives_and_engages_with_the_sensor_stamps(
        spawn: Spawn, probe: Node, tmp_path: Path) -> None:
    dwell_s = 0.3
    _proc, events, _state = _start(spawn, probe, tmp_path, engage_dwell_s=dwell_s)
    visitor = Visitor(probe)
    radar_stamp = visitor.presence(True, 1.0)
    events.wait_for(lambda e: e.kind == "ARRIVED", 20, "ARRIVED")
    retry_until(lambda: visitor.face() and _engaged(events), 30, 0.05, "ENGAGED")
    got = [(e.kind, e.engagement) for e in events.messages]
    assert got[:3] == [("ARRIVED", "NONE"), ("ENGAGEMENT_CHANGED", "ENGAGING"),
                       ("ENGAGEMENT_CHANGED", "ENGAGED")], got
    arrived, engaging, engaged = events.messages[:3]
    assert arrived.stamp_ns == radar_stamp and arrived.zone == "PERSONAL"
    assert engaging.stamp_ns in visitor.faces  # the face that began the attention
    assert engaged.stamp_ns == engaging.stamp_ns + round(dwell_s * 1e9)  # its deadline
    assert {e.person_id for e in events.messages} == {1}


@pytest.mark.integration
def test_the_state_is_latched_for_a_late_subscriber(
        spawn: Spawn, probe: Node, node_factory: Callable[..., Node], tmp_path: Path) -> None:
    _proc, _events, state = _start(spawn, probe, tmp_path)
    visitor = Visitor(probe)
    stamp = visitor.presence(True, 2.0)
    published = state.wait_for(lambda s: len(s.people) == 1, 20, "a person in the state")
    assert published.stamp_ns == stamp
    late = Collector[m.PeopleState](node_factory("late"), keys.PEOPLE_STATE)
    got = late.wait_for(lambda s: len(s.people) == 1, 20, "the latched state")
    person = got.people[0]
    assert (person.id, person.zone, person.seen_by, person.arrived_ns) == (
        1, "SOCIAL", "RADAR", stamp)


@pytest.mark.integration
def test_the_name_of_the_face_reaches_people_state_and_its_erasure_too(
        spawn: Spawn, probe: Node, tmp_path: Path) -> None:
    _proc, _events, state = _start(spawn, probe, tmp_path)
    wanted = keys.FACE_NAME.key(camera="front")
    retry_until(lambda: any(i.node == "people" and wanted in i.subscriptions
                            for i in probe.node_infos(1.0)),
                30, 0.2, "the name subscription declared")
    visitor = Visitor(probe)
    visitor.presence(True, 1.0)
    names = probe.publisher(keys.FACE_NAME, camera="front")
    retry_until(lambda: visitor.face() != 0 and any(
        p.seen_by == "BOTH" for s in state.messages for p in s.people),
        30, 0.05, "the face on the person")
    names.put(m.FaceName(stamp_ns=m.now_ns(), frame_id="camera", track=2, name="Ada",
                         score=0.95, votes=3))
    state.wait_for(lambda s: [p.name for p in s.people] == ["Ada"], 20, "the name")
    names.put(m.FaceName(stamp_ns=m.now_ns(), frame_id="camera", track=2))
    state.wait_for(lambda s: [p.name for p in s.people] == [None], 20, "the name erased")


MALFORMED = [b"\x00\xff not json", b"{}", b'{"stamp_ns": -1}', b"[1, 2, 3]"]


@pytest.mark.integration
def test_malformed_input_is_counted_and_dropped(
        spawn: Spawn, probe: Node, endpoint: str, tmp_path: Path) -> None:
    proc, events, _state = _start(spawn, probe, tmp_path)
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="people")
    inputs = [keys.PRESENCE.key(), keys.FACE.key(camera="front"),
              keys.RADAR_FRAMES.key(device="0"), keys.RADAR_TARGETS.key(device="1"),
              keys.FACE_NAME.key(camera="front")]
    wanted = {keys.PRESENCE.key(), keys.FACE.key(camera="front"), "radar/*/frames",
              "radar/*/targets", keys.FACE_NAME.key(camera="front")}
    retry_until(lambda: any(i.node == "people" and wanted <= set(i.subscriptions)
                            for i in probe.node_infos(1.0)),
                30, 0.2, "every input's subscription declared")
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", msgspec.json.encode([endpoint]).decode())
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session:
        for key in inputs:
            for payload in MALFORMED:
                # BLOCK: a burst from a bare session may otherwise be dropped on a
                # busy machine before it reaches the service, and the count is exact.
                session.put(keys.absolute("buddy", key), payload,
                            congestion_control=zenoh.CongestionControl.BLOCK)
    sent = len(inputs) * len(MALFORMED)
    counted = diag.wait_for(lambda d: int(d.values.get("malformed", 0)) >= sent,
                            30, "every malformed sample counted")
    assert int(counted.values["malformed"]) == sent
    Visitor(probe).presence(True, 1.0)
    events.wait_for(lambda e: e.kind == "ARRIVED", 20, "ARRIVED after the garbage")
    assert proc.alive()


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


@pytest.mark.integration
def test_engage_dwell_is_live(spawn: Spawn, probe: Node, endpoint: str, tmp_path: Path) -> None:
    """A dwell nobody waits out, set short while the service runs: the visitor engages."""
    proc, events, _state = _start(spawn, probe, tmp_path, engage_dwell_s=3600.0)
    visitor = Visitor(probe)
    visitor.presence(True, 1.0)
    retry_until(lambda: visitor.face() and any(
        e.engagement == "ENGAGING" for e in events.messages), 20, 0.05, "ENGAGING")
    assert not _engaged(events)

    result = param(endpoint, "set", "people", "engage_dwell_s", "0.2")
    assert result.returncode == 0, result.stderr
    assert "people.engage_dwell_s = 0.2 (applied)" in result.stdout
    retry_until(lambda: visitor.face() and _engaged(events), 20, 0.05, "ENGAGED after the set")
    retry_until(lambda: "parameters changed: engage_dwell_s=0.2" in proc.output(), 10,
                what="the change logged")
    refused = param(endpoint, "set", "people", "tick_s", "0.1")
    assert refused.returncode != 0
    assert proc.alive()


@pytest.mark.integration
def test_angle_radar_targets_are_persons(spawn: Spawn, probe: Node, tmp_path: Path) -> None:
    _proc, events, state = _start(spawn, probe, tmp_path)
    pub = probe.publisher(keys.RADAR_TARGETS, device="1")
    stamp = m.now_ns()
    retry_until(lambda: pub.put(radar_targets(stamp, (2.0, 0.5), (1.0, -1.0))) or len(
        events.messages) >= 2, 30, 0.2, "two ARRIVED")
    assert [(e.kind, e.stamp_ns) for e in events.messages[:2]] == [("ARRIVED", stamp)] * 2
    last = state.wait_for(lambda s: len(s.people) == 2, 10, "two persons")
    assert {p.seen_by for p in last.people} == {"RADAR"}
