"""What the controller needs of a bot (and the arbiter of a node), without Zenoh:
publishers and wishes that record, a diagnostics counter, and a speaker (or
calls) answered by functions the test gives. With a fake clock the controller
then runs without a router or threads."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

from buddybot.contract import messages as m
from buddybot.controller.service import Controller
from buddybot.controller.settings import ControllerSettings
from buddybot.sdk.faces import Face
from buddybot.sdk.persons import PeopleNow, person_from


@dataclass
class FakePublisher:
    sent: list[Any] = field(default_factory=list)

    def put(self, msg: Any) -> None:
        self.sent.append(msg)


@dataclass
class FakeDiagnostics:
    values: dict[str, Any] = field(default_factory=dict)

    def increment(self, name: str) -> None:
        self.values[name] = self.values.get(name, 0) + 1


def no_calls(service: Any, request: Any, timeout: float) -> Any:
    raise AssertionError(f"unexpected call of {service} with {request!r}")


class FakeNode:
    """Publishers by key pattern, diagnostics, and `call` answered by `calls`."""

    def __init__(self, calls: Callable[[Any, Any, float], Any] = no_calls) -> None:
        self.publishers: dict[str, FakePublisher] = {}
        self.diagnostics = FakeDiagnostics()
        self._calls = calls

    def publisher(self, topic: Any, **_params: str) -> FakePublisher:
        return self.publishers.setdefault(topic.pattern, FakePublisher())

    def call(self, service: Any, request: Any, *, timeout: float) -> Any:
        return self._calls(service, request, timeout)


def no_sound(what: str, arg: str) -> Any:
    raise AssertionError(f"unexpected speaker call {what}({arg!r})")


class FakeSpeaker:
    """`bot.speaker` as the controller uses it: `play(sound)` answers with an object
    carrying the goal id (or raises, as the test's `answer` does), `cancel(goal_id)`
    with whether the goal was stopped."""

    def __init__(self, answer: Callable[[str, str], Any]) -> None:
        self._answer = answer

    def play(self, sound: str, timeout: float | None = None) -> Any:
        return SimpleNamespace(goal_id=self._answer("play", sound))

    def cancel(self, goal_id: str, timeout: float) -> bool:
        return bool(self._answer("cancel", goal_id))


class FakeWishes:
    """`bot.wishes`, recorded as the messages the real one puts, on its keys."""

    def __init__(self, publishers: dict[str, FakePublisher]) -> None:
        self._expression = publishers.setdefault("controller/expression", FakePublisher())
        self._gaze = publishers.setdefault("controller/eye_control", FakePublisher())

    def express(self, expression: m.ExpressionAction) -> None:
        self._expression.put(m.ScreenExpression(stamp_ns=m.now_ns(), action=expression))

    def look_at(self, yaw: float, pitch: float, distance_m: float | None = None,
                stamp_ns: int | None = None) -> None:
        self._gaze.put(m.EyeControl(
            stamp_ns=m.now_ns() if stamp_ns is None else stamp_ns, yaw=yaw, pitch=pitch,
            target_distance_cm=0.0 if distance_m is None else distance_m * 100))


class FakeBot:
    """The built-in `Bot` the controller is attached to: wishes, publishers by key
    pattern, diagnostics, and a speaker answered by `answer(what, arg)`."""

    def __init__(self, answer: Callable[[str, str], Any] = no_sound) -> None:
        self.publishers: dict[str, FakePublisher] = {}
        self.diagnostics = FakeDiagnostics()
        self.wishes = FakeWishes(self.publishers)
        self.speaker = FakeSpeaker(answer)

    def publisher(self, topic: Any, **_params: str) -> FakePublisher:
        return self.publishers.setdefault(topic.pattern, FakePublisher())


class Clock:
    """A monotonic clock that moves only when the test says so."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def people_now(msg: m.PeopleState) -> PeopleNow:
    """`people/state` as the SDK hands it to a `bot.people.on_state` callback."""
    return PeopleNow(tuple(person_from(p) for p in msg.people), msg.stamp_ns)


def face(x: float = 1.0, y: float = 0.0, z: float = 0.0, stamp_ns: int = 1) -> Face:
    """A face as `bot.on_face` hands it over (metres in the camera's frame)."""
    return Face(x, y, z, stamp_ns=stamp_ns, confidence=0.9)


def attached(settings: ControllerSettings, clock: Clock) -> tuple[Controller, FakeBot]:
    """A controller on `clock`, attached to a fake bot but not started."""
    controller = Controller(settings, clock=clock)
    bot = FakeBot()
    controller.attach(bot)  # type: ignore[arg-type]
    return controller, bot
