"""The intake between Zenoh's thread and the presence rule (threads only, no I/O)."""

from __future__ import annotations

import threading

from buddybot.radar.intake import Intake
from buddybot.tools.testing import retry_until


class Recorder:
    """A handler that blocks until released, then records what it handled."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.started = threading.Event()
        self.handled: list[tuple[str, int]] = []

    def __call__(self, key: str, item: int) -> None:
        self.started.set()
        self.release.wait(10)
        self.handled.append((key, item))


def test_trusted_keys_are_served_first_and_never_dropped_by_a_flood() -> None:
    rec = Recorder()
    intake: Intake[int] = Intake(rec, general_size=8, per_key=4, max_trusted=2).start()
    try:
        intake.trust("radar/0/frames")
        intake.submit("evil/0", -1)  # occupies the worker
        assert rec.started.wait(10)
        for i in range(10_000):  # the flood, while the real sensor keeps reporting
            intake.submit(f"evil/{i}", i)
            if i % 1000 == 0:
                intake.submit("radar/0/frames", i)
        rec.release.set()
        retry_until(lambda: intake.pending() == 0, 10, what="intake drained")
    finally:
        intake.close()
    real = [item for key, item in rec.handled if key == "radar/0/frames"]
    # A lane keeps the newest per_key frames of a trusted key; they go first.
    assert real == [6000, 7000, 8000, 9000]
    assert [key for key, _ in rec.handled[1:5]] == ["radar/0/frames"] * 4
    assert intake.dropped == 10_000 - 8 and intake.dropped_trusted == 6
    assert len(rec.handled) == 1 + 4 + 8


def test_trusted_keys_take_turns_and_are_bounded() -> None:
    rec = Recorder()
    intake: Intake[int] = Intake(rec, general_size=8, per_key=8, max_trusted=2).start()
    try:
        intake.trust("a")
        intake.trust("b")
        intake.submit("x", 0)
        assert rec.started.wait(10)
        for i in range(3):
            intake.submit("a", i)
        for i in range(3):
            intake.submit("b", i)
        intake.trust("c")  # a third trusted key: the least recently active loses its lane
        assert sorted(intake.trusted()) == ["b", "c"]
        rec.release.set()
        retry_until(lambda: intake.pending() == 0, 10, what="intake drained")
    finally:
        intake.close()
    assert rec.handled == [("x", 0), ("b", 0), ("b", 1), ("b", 2)]
    assert intake.dropped_trusted == 3  # "a"'s pending frames went with its lane


def test_a_failing_handler_does_not_stop_the_worker() -> None:
    seen: list[int] = []
    errors: list[BaseException] = []

    def handler(key: str, item: int) -> None:
        if item == 1:
            raise ValueError("bad frame")
        seen.append(item)

    intake: Intake[int] = Intake(handler, on_error=errors.append).start()
    try:
        for i in range(3):
            intake.submit("k", i)
        retry_until(lambda: len(seen) == 2, 10, what="items handled")
    finally:
        intake.close()
    assert seen == [0, 2] and len(errors) == 1
