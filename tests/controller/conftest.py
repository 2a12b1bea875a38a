"""Scenario fixtures: a fake audio action server and a face/presence stimulus, both
real Zenoh nodes in the test process talking to the controller process through
the real router. The stimulus stands in for the people service (its latched
`people/state`), so these tests are about the controller alone; the chain
radar/presence -> people -> controller has its own test in test_service.py."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node, new_goal_id
from buddybot.tools.testing import visitor

# The alone phase and the alert have tests of their own (test_behaviour, test_attention).
FAST_CONFIG = """
[controller]
farewell_delay_s = 0.8
gaze_hold_s = 0.6
look_around_after_s = 1.5
greet_dwell_s = 0.5
regreet_cooldown_s = 30.0
alone_s = 0.0
alert_s = 0.0
sleepy_s = 0.5
farewell_max_delay_s = 10.0
recover_s = 0.3

[controller.camera_to_eyes]
translation_m = [0.0, 0.0, 0.1]
rpy_rad = [0.0, 0.0, 0.0]
"""


class FakeAudio:
    """Serves `audio/play_sound` and its cancel like the real action server:
    reply accepted with a goal id, status ACCEPTED -> PLAYING -> SUCCEEDED or
    CANCELED, `device_free` false while playing. Records every request."""

    def __init__(self, node: Node, durations: dict[str, float] | None = None,
                 refuse: set[str] | None = None) -> None:
        self.node = node
        self.durations = durations or {}
        self.refuse = refuse or set()
        self.goals: list[tuple[str, str]] = []  # (sound, goal_id)
        self.cancels: list[str] = []
        self.log: list[str] = []  # "play:greeting", "cancel:greeting", "end:greeting"
        self.overlaps = 0
        self._playing: dict[str, tuple[str, threading.Event]] = {}
        self._lock = threading.Condition()
        self._status = node.publisher(keys.PLAY_SOUND_STATUS)
        self._free = node.publisher(keys.DEVICE_FREE)
        self._free.put(m.Bool(stamp_ns=m.now_ns(), data=True))
        node.serve(keys.PLAY_SOUND, self._play)
        node.serve(keys.PLAY_SOUND_CANCEL, self._cancel)

    def _put_status(self, goal_id: str, state: str, progress: float = 0.0) -> None:
        # The test may end while a sound is still "playing": its node is then closed.
        with contextlib.suppress(zenoh.ZError):
            self._status.put(m.PlaySoundStatus(
                goal_id=goal_id, state=state, progress=progress,  # type: ignore[arg-type]
                stamp_ns=m.now_ns()))

    def _play(self, req: m.PlaySound) -> m.PlaySoundReply:
        if req.sound in self.refuse:
            with self._lock:
                self.log.append(f"refused:{req.sound}")
                self._lock.notify_all()
            return m.PlaySoundReply(goal_id="", accepted=False, message="refused by test")
        goal_id = new_goal_id()
        stop = threading.Event()
        with self._lock:
            if self._playing:
                self.overlaps += 1
            self._playing[goal_id] = (req.sound, stop)
            self.goals.append((req.sound, goal_id))
            self.log.append(f"play:{req.sound}")
            self._lock.notify_all()
        self._put_status(goal_id, "ACCEPTED")
        self._free.put(m.Bool(stamp_ns=m.now_ns(), data=False))
        self._put_status(goal_id, "PLAYING")
        threading.Thread(target=self._run, args=(goal_id, req.sound, stop), daemon=True).start()
        return m.PlaySoundReply(goal_id=goal_id, accepted=True)

    def _run(self, goal_id: str, sound: str, stop: threading.Event) -> None:
        cancelled = stop.wait(self.durations.get(sound, 0.5))
        with self._lock:
            self._playing.pop(goal_id, None)
            self.log.append(f"{'canceled' if cancelled else 'end'}:{sound}")
            self._lock.notify_all()
        self._put_status(goal_id, "CANCELED" if cancelled else "SUCCEEDED", 1.0)
        with contextlib.suppress(zenoh.ZError):
            self._free.put(m.Bool(stamp_ns=m.now_ns(), data=True))

    def _cancel(self, req: m.CancelGoal) -> m.TriggerReply:
        with self._lock:
            entry = self._playing.get(req.goal_id)
            self.cancels.append(req.goal_id)
            self.log.append(f"cancel:{entry[0] if entry else '?'}")
            self._lock.notify_all()
        if entry is None:
            return m.TriggerReply(success=False, message="no such goal")
        entry[1].set()
        return m.TriggerReply(success=True)

    def sounds(self) -> list[str]:
        with self._lock:
            return [s for s, _ in self.goals]

    def wait_log(self, predicate: Callable[[list[str]], bool], timeout: float = 15.0,
                 what: str = "audio log") -> list[str]:
        with self._lock:
            if not self._lock.wait_for(lambda: predicate(self.log), timeout):
                raise TimeoutError(f"{what} not met within {timeout} s: {self.log}")
            return list(self.log)


class Stimulus:
    """The people service and the camera of a scenario: one visitor the radar sees or
    not (`people/state`, latched) and a face stream."""

    def __init__(self, node: Node, camera: str = "front") -> None:
        self.people_pub = node.publisher(keys.PEOPLE_STATE)
        self.face_pub = node.publisher(keys.FACE, camera=camera)
        self.point = m.Point(x=1.0, y=0.3, z=0.0)
        self._watching = threading.Event()
        self._said: tuple[bool, float, int] | None = None
        self._stop = threading.Event()
        self.faces_sent = 0
        self._thread = threading.Thread(target=self._stream, daemon=True)
        self._thread.start()

    def presence(self, in_range: bool, distance_m: float = 1.2, person_id: int = 1) -> None:
        self._said = (in_range, distance_m, person_id)
        self.people_pub.put(visitor(in_range, person_id, distance_m,
                                    face=self._watching.is_set()))

    def face(self, stamp_ns: int | None = None) -> int:
        stamp = stamp_ns if stamp_ns is not None else m.now_ns()
        self.face_pub.put(m.FacePosition(stamp_ns=stamp, frame_id="front",
                                         point=self.point, confidence=0.9))
        self.faces_sent += 1
        return stamp

    def watch(self, on: bool) -> None:
        """Start/stop a face stream at 10 frames/s (a camera that sees someone), and
        say so in the people state, as the people service does for its faces."""
        (self._watching.set if on else self._watching.clear)()
        if self._said is not None:
            self.presence(*self._said)

    def _stream(self) -> None:
        while not self._stop.wait(0.1):
            if self._watching.is_set():
                self.face()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


@pytest.fixture
def fast_config(tmp_path: Path) -> Path:
    path = tmp_path / "controller.toml"
    path.write_text(FAST_CONFIG)
    return path


@pytest.fixture
def stimulus(node_factory: Callable[..., Node]) -> Iterator[Stimulus]:
    stim = Stimulus(node_factory("stimulus"))
    yield stim
    stim.close()


@pytest.fixture
def make_audio(node_factory: Callable[..., Node]) -> Callable[..., FakeAudio]:
    def make(**kwargs: Any) -> FakeAudio:
        return FakeAudio(node_factory("fake-audio"), **kwargs)

    return make
