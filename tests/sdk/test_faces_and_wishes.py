"""`bot.on_face`, `bot.people.on_state`, `bot.wishes`, the speaker's and the leases'
callbacks, and `bot.params.offer`: what the robot's own behaviour asks of the
SDK, through the real router."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Annotated

import msgspec
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.sdk import Bot, SdkError
from buddybot.sdk.faces import Face
from buddybot.sdk.persons import PeopleNow
from buddybot.sdk.speaker import GoalStatus
from buddybot.tools.testing import Collector, retry_until, visitor

pytestmark = pytest.mark.integration


class Box:
    """What callbacks handed over, with a wait on it."""

    def __init__(self) -> None:
        self.items: list[object] = []
        self._cond = threading.Condition()

    def put(self, item: object) -> None:
        with self._cond:
            self.items.append(item)
            self._cond.notify_all()

    def wait(self, check: Callable[[list[object]], bool], what: str) -> list[object]:
        with self._cond:
            if not self._cond.wait_for(lambda: check(self.items), 15.0):
                raise TimeoutError(f"{what}: {self.items}")
            return list(self.items)


def test_faces_come_as_faces_of_the_camera_asked_for(bot_factory: Callable[..., Bot],
                                                      probe: Node) -> None:
    bot = bot_factory(name="face-watcher")
    got = Box()
    handle = bot.on_face(got.put, camera="side")
    side = probe.publisher(keys.FACE, camera="side")
    front = probe.publisher(keys.FACE, camera="front")
    point = m.Point(x=1.5, y=-0.2, z=0.1)
    stamp = m.now_ns()

    def send() -> bool:
        front.put(m.FacePosition(stamp_ns=stamp, frame_id="front", point=point,
                                 confidence=0.5))
        side.put(m.FacePosition(stamp_ns=stamp, frame_id="side", point=point, confidence=0.8,
                                track=3))
        return bool(got.items)

    retry_until(send, 15, 0.1, "a face from the side camera")
    face = got.items[0]
    assert face == Face(1.5, -0.2, 0.1, stamp_ns=stamp, confidence=0.8, track=3,
                        camera="side")
    assert all(isinstance(f, Face) and f.camera == "side" for f in got.items)
    handle.close()
    with pytest.raises(ValueError, match="camera name"):
        bot.on_face(got.put, camera="a/b")


def test_on_state_gives_the_latched_state_first_then_each_one(
        bot_factory: Callable[..., Bot], probe: Node) -> None:
    state = probe.publisher(keys.PEOPLE_STATE)
    state.put(visitor(True, person_id=4, distance_m=1.5))
    bot = bot_factory(name="state-watcher")
    got = Box()
    watch = bot.people.on_state(got.put)
    first = got.wait(lambda items: bool(items), "the latched people/state")[0]
    assert isinstance(first, PeopleNow)
    assert [(p.id, p.seen_by, p.distance_m) for p in first.people] == [(4, "RADAR", 1.5)]
    state.put(visitor(False, person_id=4, held=True))
    got.wait(lambda items: any(isinstance(i, PeopleNow) and i.people
                               and i.people[0].seen_by == "NONE" for i in items),
             "the held person")
    watch.close()


def test_only_the_builtin_bot_has_wishes_and_they_reach_the_arbiters_keys(
        bot_factory: Callable[..., Bot], probe: Node, node_factory: Callable[..., Node]
) -> None:
    app = bot_factory(name="some-app")
    with pytest.raises(SdkError, match=r"bot\.eyes"):
        app.wishes  # noqa: B018
    builtin = Bot(node_factory("builtin-behaviour"), builtin=True)
    try:
        expressions = Collector[m.ScreenExpression](probe, keys.BEHAVIOUR_EXPRESSION)
        gazes = Collector[m.EyeControl](probe, keys.BEHAVIOUR_GAZE)

        stamp = m.now_ns()

        def wish() -> bool:
            builtin.wishes.express("grin")
            builtin.wishes.look_at(0.3, -0.1, 1.25, stamp_ns=stamp)
            return bool(expressions.messages and gazes.messages)

        retry_until(wish, 15, 0.1, "the wishes on controller/*")
        assert expressions.messages[-1].action == m.ExpressionAction.EYE_GRIN
        gaze = gazes.messages[-1]
        assert (gaze.stamp_ns, gaze.yaw, gaze.pitch) == (stamp, 0.3, -0.1)
        assert gaze.target_distance_cm == pytest.approx(125.0)
        with pytest.raises(ValueError, match="yaw"):
            builtin.wishes.look_at(9.0, 0.0)
    finally:
        builtin.close()


def test_speaker_statuses_and_device_free_reach_every_watcher(
        bot_factory: Callable[..., Bot], probe: Node) -> None:
    status = probe.publisher(keys.PLAY_SOUND_STATUS)
    free = probe.publisher(keys.DEVICE_FREE)
    status.put(m.PlaySoundStatus(goal_id="g-old", state="SUCCEEDED", stamp_ns=5))
    free.put(m.Bool(stamp_ns=5, data=True))
    bot = bot_factory(name="speaker-watcher")
    statuses, frees = Box(), Box()
    bot.speaker.on_status(statuses.put)
    bot.speaker.on_free(frees.put)
    statuses.wait(lambda items: GoalStatus("g-old", "SUCCEEDED", "", 5) in items,
                  "the latched status of a goal that ended before")
    frees.wait(lambda items: items[:1] == [True], "the latched device_free")
    status.put(m.PlaySoundStatus(goal_id="g-new", state="PLAYING", stamp_ns=6))
    free.put(m.Bool(stamp_ns=6, data=False))
    statuses.wait(lambda items: any(getattr(i, "goal_id", "") == "g-new" for i in items),
                  "a live status")
    frees.wait(lambda items: items[-1] is False, "the player busy")


def test_on_held_names_the_parts_any_lease_holds(bot_factory: Callable[..., Bot],
                                                 probe: Node) -> None:
    leases = probe.publisher(keys.LEASES)
    bot = bot_factory(name="lease-watcher")
    held = Box()
    bot.leases.on_held(held.put)

    def state(*resources: m.Resource) -> m.Leases:
        return m.Leases(stamp_ns=m.now_ns(), leases=[m.Lease(
            lease_id="L1-x", holder="other-app", instance="i", priority="app",
            resources=list(resources), granted_ns=1)] if resources else [])

    retry_until(lambda: leases.put(state("audio", "gaze")) or held.items, 15, 0.1,
                "the first leases/state")
    assert held.items[-1] == ("gaze", "audio")  # the contract's order, each once
    leases.put(state())
    held.wait(lambda items: items[-1] == (), "nothing held")


class Knobs(msgspec.Struct, forbid_unknown_fields=True):
    volume: Annotated[int, msgspec.Meta(ge=0, extra={"live": True})] = 3
    device: str = "default"  # restart-only: not marked live


def test_a_program_offers_its_own_live_parameters(bot_factory: Callable[..., Bot]) -> None:
    owner = bot_factory(name="knob-owner")
    applied: list[Knobs] = []

    def apply(new: Knobs) -> None:
        if new.volume > 10:
            raise ValueError("too loud")
        applied.append(new)

    owner.params.offer(Knobs(), apply)
    other = bot_factory(name="knob-user")
    retry_until(lambda: other.params.get("knob-owner", "volume", timeout=2.0) == 3, 15, 0.2,
                "the offered parameters")
    assert other.params.set("knob-owner", "volume", 7) is True
    assert applied == [Knobs(volume=7)]
    with pytest.raises(SdkError, match="too loud"):
        other.params.set("knob-owner", "volume", 11)
    assert other.params.get("knob-owner", "volume") == 7
    with pytest.raises(SdkError, match="restart"):
        other.params.set("knob-owner", "device", "usb")
