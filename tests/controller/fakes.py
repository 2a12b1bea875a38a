"""What `Controller` needs of a node, without Zenoh: publishers that record, a
diagnostics counter, and audio calls answered by a function the test gives.
With a fake clock the controller then runs without a router or threads."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


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


class Clock:
    """A monotonic clock that moves only when the test says so."""

    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t
