"""The people model as ROS4HRI (services/ros2/hri.py): the plan from `people/state`
(pure), its CDR read by mcap-ros2-support's decoder from definitions written
here from REP-155, and the topics live on the bridge as a plain Zenoh peer
sees them (opened when a person arrives, gone from the graph when they leave)."""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator
from typing import Any

import msgspec
import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.ros2 import bridge, hri, hri_msgs, service, types, wire
from buddybot.ros2.settings import Ros2Settings
from buddybot.runtime.node import Node, zenoh_config
from buddybot.tools.testing import Collector, Process, retry_until, visitor

from .test_convert import their_decoder
from .test_service import late_sample, subscription_token

SEPARATOR = "=" * 80
HEADER = (f"{SEPARATOR}\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
          f"{SEPARATOR}\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n")
SCHEMAS = {
    hri_msgs.IDS_LIST: "std_msgs/Header header\nstring[] ids\n" + HEADER,
    hri_msgs.ENGAGEMENT_LEVEL: ("std_msgs/Header header\nuint8 UNKNOWN=0\nuint8 DISENGAGED=1\n"
                                "uint8 ENGAGING=2\nuint8 ENGAGED=3\nuint8 DISENGAGING=4\n"
                                "uint8 level\n" + HEADER),
    types.FLOAT32: "float32 data\n",
    types.BOOL: "bool data\n",
    types.STRING: "string data\n",
    types.TF_MESSAGE: (
        "geometry_msgs/TransformStamped[] transforms\n"
        f"{SEPARATOR}\nMSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\n"
        "string child_frame_id\ngeometry_msgs/Transform transform\n"
        f"{SEPARATOR}\nMSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\n"
        "geometry_msgs/Quaternion rotation\n"
        f"{SEPARATOR}\nMSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
        f"{SEPARATOR}\nMSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\n"
        "float64 w 1\n" + HEADER),
}
"""The types as REP-155 and ROS 2 Jazzy define them: an independent reading."""


def decode(sample: hri.Sample) -> Any:
    return their_decoder(sample.ros_type, SCHEMAS[sample.ros_type])(sample.payload)


def person(pid: int, **fields: Any) -> m.Person:
    base = visitor(True, pid, 2.0).people[0]
    return msgspec.structs.replace(base, **fields)


def state(*people: m.Person, stamp_ns: int = 1_700_000_000_000_000_000) -> m.PeopleState:
    return m.PeopleState(stamp_ns=stamp_ns, people=list(people))


def by_name(plan: hri.Plan) -> dict[str, Any]:
    return {s.name: decode(s) for s in plan.samples}


def test_a_visit_opens_its_topics_sends_changes_only_and_closes_them() -> None:
    planner = hri.HriPlanner(robot_frame="base_link")
    ada = person(7, engagement="ENGAGED", yaw_rad=0.5, pitch_rad=0.0, seen_by="BOTH",
                 name="Ada Lovelace")
    first = planner.step(state(ada))
    assert (first.opened, first.closed) == (("p7",), ())
    got = by_name(first)
    assert got["humans/persons/tracked"].ids == ["p7"]
    assert got["humans/persons/known"].ids == ["p7", "known_ada_lovelace"]
    assert got["humans/persons/p7/engagement_status"].level == 3  # ENGAGED
    assert got["humans/persons/p7/location_confidence"].data == 1.0
    assert got["humans/persons/p7/anonymous"].data is False
    assert got["humans/persons/p7/alias"].data == "known_ada_lovelace"
    [frame] = got["tf"].transforms
    assert (frame.header.frame_id, frame.child_frame_id) == ("base_link", "person_p7")
    t = frame.transform.translation
    assert (t.x, t.y, t.z) == pytest.approx((2 * math.cos(0.5), 2 * math.sin(0.5), 0.0))
    assert frame.header.stamp.sec == 1_700_000_000

    again = planner.step(state(ada, stamp_ns=1_700_000_001_000_000_000))
    assert [s.name for s in again.samples] == ["tf"]  # nothing else changed
    looked_away = planner.step(state(msgspec.structs.replace(ada, engagement="DISENGAGING")))
    assert [s.name for s in looked_away.samples] == ["humans/persons/p7/engagement_status", "tf"]

    gone = planner.step(state())
    assert (gone.opened, gone.closed) == ((), ("p7",))
    assert {s.name: decode(s).ids for s in gone.samples} == {
        "humans/persons/tracked": [], "humans/persons/known": []}


def test_frames_come_at_most_every_tenth_of_a_second_and_at_once_for_a_newcomer() -> None:
    planner = hri.HriPlanner()
    ada = person(1, yaw_rad=0.1, seen_by="BOTH")
    bob = person(2, yaw_rad=-0.3, seen_by="BOTH")
    t0 = 1_700_000_000_000_000_000
    sent = []
    for i, people in enumerate([(ada,)] * 4 + [(ada, bob)] + [(ada, bob)] * 6):
        plan = planner.step(state(*people, stamp_ns=t0 + i * 33_000_000))
        sent.append(any(s.name == "tf" for s in plan.samples))
    # every 33 ms: the first; bob at once (132 ms); then not before 0.1 s after him
    assert sent == [True, False, False, False, True, False, False, False, True, False, False]


def test_a_state_that_only_moves_someone_sends_nothing_until_a_frame_is_due() -> None:
    planner = hri.HriPlanner()
    ada = person(1, yaw_rad=0.1, seen_by="BOTH", engagement="ENGAGING")
    t0 = 1_700_000_000_000_000_000
    assert "tf" in by_name(planner.step(state(ada, stamp_ns=t0)))
    closer = msgspec.structs.replace(ada, distance_m=1.5)
    assert planner.step(state(closer, stamp_ns=t0 + 40_000_000)).samples == ()
    engaged = msgspec.structs.replace(closer, engagement="ENGAGED")
    at_once = planner.step(state(engaged, stamp_ns=t0 + 80_000_000))
    assert [s.name for s in at_once.samples] == ["humans/persons/p1/engagement_status"]
    unseen = msgspec.structs.replace(engaged, yaw_rad=None)  # a distance only now
    lost = by_name(planner.step(state(unseen, stamp_ns=t0 + 90_000_000)))
    assert list(lost) == ["humans/persons/p1/location_confidence"]
    back = planner.step(state(engaged, stamp_ns=t0 + 95_000_000))
    assert [s.name for s in back.samples] == ["humans/persons/p1/location_confidence"]
    due = by_name(planner.step(state(engaged, stamp_ns=t0 + 100_000_000)))
    assert list(due) == ["tf"]  # the period passed: where they are now
    assert due["tf"].transforms[0].transform.translation.x == pytest.approx(1.5 * math.cos(0.1))
    assert planner.step(state(engaged, stamp_ns=t0 + 150_000_000)).samples == ()


PEOPLE = st.builds(
    person, st.integers(1, 3), engagement=st.sampled_from([*hri.LEVELS, "GONE"]),
    seen_by=st.sampled_from(["NONE", "RADAR", "CAMERA", "BOTH"]),
    yaw_rad=st.none() | st.floats(-1.0, 1.0), bearing_rad=st.none() | st.floats(-1.0, 1.0),
    distance_m=st.floats(0.3, 5.0), name=st.none() | st.sampled_from(["Ada", "Bob"]))
STATES = st.lists(st.tuples(st.integers(-50_000_000, 150_000_000),
                            st.lists(PEOPLE, max_size=3, unique_by=lambda p: p.id)),
                  max_size=30)


@given(STATES)
def test_a_skipped_state_is_one_that_had_nothing_to_send(steps: list[tuple[int, list[m.Person]]]
                                                         ) -> None:
    quick, full = hri.HriPlanner(), hri.HriPlanner()
    stamp = 1_700_000_000_000_000_000
    for dt, people in steps:
        stamp += dt  # now and then the clock goes back
        full.shown = None  # this one plans every state in full
        assert quick.step(state(*people, stamp_ns=stamp)) == full.step(
            state(*people, stamp_ns=stamp))


def test_a_person_without_a_direction_has_no_frame_and_no_confidence() -> None:
    planner = hri.HriPlanner()
    plan = by_name(planner.step(state(person(2, engagement="NONE"))))  # an LD2410's distance
    assert plan["humans/persons/p2/location_confidence"].data == 0.0
    assert plan["humans/persons/p2/engagement_status"].level == 1  # DISENGAGED
    assert plan["humans/persons/p2/anonymous"].data is True
    assert "tf" not in plan and "humans/persons/p2/alias" not in plan
    held = by_name(planner.step(state(person(2, bearing_rad=-0.2, seen_by="NONE"))))
    assert held["humans/persons/p2/location_confidence"].data == 0.5


@given(st.text(max_size=40))
def test_an_identity_id_is_a_ros_name_token(name: str) -> None:
    ident = hri.identity_id(name)
    assert ident.startswith("known_") and ident.replace("_", "").isalnum()
    assert ident.isascii() and ident == ident.lower()


def test_the_hri_types_hash_as_pinned() -> None:
    """The RIHS01 hashes of the two hri_msgs definitions written here (a change of
    the text changes what every ROS 2 peer must match)."""
    assert types.type_hash(hri_msgs.IDS_LIST) == (
        "RIHS01_7e0812d1ac945c98fd3e393568d581ad0ab567f37b24eff633eab778c1bfe62d")
    assert types.type_hash(hri_msgs.ENGAGEMENT_LEVEL) == (
        "RIHS01_275391f46d2e6cc0d21085f8e02dce6a8150baa57539ec99bd9f4e0321443788")


def test_every_topic_has_its_qos() -> None:
    assert hri.qos(hri.TRACKED) == hri.qos("humans/persons/p1/alias") == bridge.LATCHED_QOS
    assert hri.qos(hri.TF) == hri.qos("humans/persons/p1/location_confidence") == \
        bridge.DEFAULT_QOS


# --- live, on the bridge ----------------------------------------------------------------

SETTINGS = Ros2Settings(domain_id=5)


@pytest.fixture
def peer(endpoint: str) -> Iterator[zenoh.Session]:
    session = zenoh.open(zenoh_config(connect=[endpoint]))
    yield session
    session.close()


def publishers(peer: zenoh.Session) -> set[str]:
    names = set()
    for reply in peer.liveliness().get(f"{wire.PREFIX}/{SETTINGS.domain_id}/**", timeout=2.0):
        if reply.ok is not None:
            token = wire.GraphToken.parse(str(reply.ok.key_expr))
            if token.kind == "MP" and token.name:
                names.add(token.name)
    return names


@pytest.mark.integration
def test_while_a_persons_topics_open_only_the_newest_state_waits(
        probe: Node, monkeypatch: pytest.MonkeyPatch) -> None:
    ros = service.Ros2Bridge(probe, SETTINGS)
    for name, ros_type in hri.STATIC_TOPICS.items():
        ros._hri_topic(name, ros_type)
    declaring, go_on = threading.Event(), threading.Event()
    declare = ros._hri_topic

    def slow(name: str, ros_type: str) -> None:
        declaring.set()
        go_on.wait(30)
        declare(name, ros_type)

    monkeypatch.setattr(ros, "_hri_topic", slow)
    ada, bob = person(1, yaw_rad=0.1, seen_by="BOTH"), person(2, yaw_rad=0.2, seen_by="BOTH")
    t0 = m.now_ns()
    try:
        ros.on_people(state(ada, stamp_ns=t0), "people/state")  # opens p1: on the worker
        assert declaring.wait(30)
        ros.on_people(state(ada, bob, stamp_ns=t0 + 10_000_000), "people/state")
        ros.on_people(state(ada, stamp_ns=t0 + 20_000_000), "people/state")  # bob left
        assert ros.sent == {}  # nothing overtakes the plan being declared
        go_on.set()
        retry_until(lambda: not ros._people_busy, 30, 0.05, "the worker done")
        assert ros.sent == {name: 1 for name in (
            hri.TRACKED, hri.KNOWN, hri.TF, *(f"humans/persons/p1/{topic}" for topic in
                                              ("engagement_status", "location_confidence",
                                               "anonymous")))}  # bob never came
        assert not any(name.startswith("humans/persons/p2/") for name in ros._hri)
        ros.on_people(state(ada, stamp_ns=t0 + 150_000_000), "people/state")
        assert ros.sent[hri.TF] == 2  # a frame due: sent in this thread, at once
    finally:
        go_on.set()
        ros.close()


@pytest.mark.integration
def test_persons_as_a_ros_2_peer_sees_them(spawn: Callable[..., Process], peer: zenoh.Session,
                                           probe: Node) -> None:
    spawn("ros2-bridge", "--domain-id", str(SETTINGS.domain_id))
    retry_until(lambda: "/humans/persons/tracked" in publishers(peer), 30, 0.2,
                "the bridge's ROS4HRI publishers")
    tracked = bridge.route(SETTINGS, hri.TRACKED, hri_msgs.IDS_LIST)
    lists: list[list[str]] = []
    came = threading.Condition()

    def on_tracked(sample: zenoh.Sample) -> None:
        ids = their_decoder(hri_msgs.IDS_LIST, SCHEMAS[hri_msgs.IDS_LIST])(
            sample.payload.to_bytes()).ids
        with came:
            lists.append(ids)
            came.notify_all()

    peer.declare_subscriber(tracked.key, on_tracked)
    people = probe.publisher(keys.PEOPLE_STATE)
    people.put(state(person(9), stamp_ns=m.now_ns()))
    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="ros2-bridge")
    diag.wait_for(lambda d: "readers /humans/persons/tracked" in d.values, 30,
                  "the bridge's diagnostics")
    assert lists == []  # no ROS 2 node reads the people yet: the bridge does not either
    token = peer.liveliness().declare_token(
        subscription_token(peer, tracked, SETTINGS.domain_id, bridge.LATCHED_QOS))
    garbage = probe.raw_publisher(probe.key(keys.PEOPLE_STATE), keys.PEOPLE_STATE.encoding)
    for payload in (b"{", b'{"stamp_ns": -1, "people": []}', b"\xff" * 100,
                    b'{"stamp_ns": 1, "people": [' + b"{}," * 100 + b"{}]}"):
        garbage.put(payload)  # dropped and counted by the node: the bridge goes on
    ada = person(4, engagement="ENGAGED", yaw_rad=0.2, seen_by="BOTH")

    def seen(ids: list[str]) -> Callable[[], bool]:
        def check() -> bool:
            with came:
                return bool(lists) and lists[-1] == ids
        return check

    retry_until(lambda: people.put(state(ada, stamp_ns=m.now_ns())) or seen(["p4"])(), 30, 0.3,
                "p4 tracked")
    engagement = bridge.route(SETTINGS, "humans/persons/p4/engagement_status",
                              hri_msgs.ENGAGEMENT_LEVEL)
    latched = late_sample(peer, engagement.key)
    assert their_decoder(hri_msgs.ENGAGEMENT_LEVEL, SCHEMAS[hri_msgs.ENGAGEMENT_LEVEL])(
        latched).level == 3
    assert {"/humans/persons/p4/engagement_status", "/humans/persons/p4/alias",
            "/tf"} <= publishers(peer)

    retry_until(lambda: people.put(state(stamp_ns=m.now_ns())) or seen([])(), 30, 0.3,
                "nobody tracked")
    retry_until(lambda: not any(n.startswith("/humans/persons/p4/") for n in publishers(peer)),
                15, 0.2, "p4's topics gone from the graph")
    token.undeclare()

