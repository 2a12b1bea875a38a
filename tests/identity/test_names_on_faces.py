"""A name is only ever on its own face, through the real services.

The real camera plays real photos one after another, Obama on the image's
left then Biden on its right, again and again; the real face detector
follows each in turn (a new track at each switch), the real identity
service names the tracks from a gallery of both, and the real people
service puts the names on the person. At no instant may `people/state`
show a person whose name is not the face in the same message: the
direction says whose face it is (Obama's on the robot's left, + yaw).
The real controller then greets by name: the name it says is the face
the people service shows at that moment. Marked `integration`.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from buddybot.camera.sim import compose
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.identity import embedding
from buddybot.identity import gallery as gal
from buddybot.runtime.node import Node
from buddybot.sim.faces import path as photo_path
from buddybot.tools.testing import Collector, Process, retry_until
from tests.identity.conftest import key
from tests.identity.photos import detection, detectors

pytestmark = pytest.mark.integration

WHO = {"obama": ("Barack", 190), "biden": ("Joe", 450)}
"""Photo -> (the name enrolled, where the face is in the image: its x, px)."""
BLOCK = 45
"""Frames of one face before the other (3 s at 15 frames/s: named within it also on a
busy machine)."""


def frames(folder: Path) -> tuple[str, dict[str, np.ndarray]]:
    """The image sequence (one block of each face) and one frame of each face."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(2)
    one: dict[str, np.ndarray] = {}
    i = 0
    for face, (_name, u) in WHO.items():
        sprite = cv2.imread(str(photo_path(face)), cv2.IMREAD_COLOR)
        assert sprite is not None
        for _ in range(BLOCK):
            background = rng.integers(70, 110, (480, 640, 3), dtype=np.uint8)
            frame = compose(background, sprite, None, u, 230, 220)
            cv2.imwrite(str(folder / f"{i:04d}.png"), frame)
            one.setdefault(face, frame)
            i += 1
    return str(folder / "%04d.png"), one


def enrolled(path: Path, shown: dict[str, np.ndarray]) -> Path:
    """A gallery of both, embedded from the very frames the camera shows."""
    embedder = embedding.Embedder.load()
    nets = detectors()
    g = gal.Gallery(embedding.MODEL_ID)
    for face, frame in shown.items():
        name = WHO[face][0]
        g.enrol(name, [embedder.face(frame, detection(nets, frame).keypoints)], time.time())
    gal.save(path, g, key())
    return path


def test_no_person_ever_carries_the_name_of_a_face_not_theirs(
        spawn: Callable[..., Process], probe: Node, tmp_path: Path) -> None:
    pattern, shown = frames(tmp_path / "frames")
    config = tmp_path / "robot.toml"
    config.write_text(f'[identity]\ngallery = "{enrolled(tmp_path / "gallery.bin", shown)}"\n'
                      "every_nth = 1\n")
    state = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
    spawn("people", "--config", str(config))
    spawn("identity", "--config", str(config))
    spawn("face-detector", "--config", str(config))
    spawn("camera", "--config", str(config), "--source", pattern, "--fps", "15", "--loop")

    def named() -> set[str]:
        return {p.name for s in state.messages for p in s.people if p.name}

    retry_until(lambda: named() == {"Barack", "Joe"}, 300, 0.2, "both faces named")
    start = len(state.messages)

    def switches() -> int:
        """Changes of the name shown since `start` (a withdrawn name in between is none)."""
        shown = [p.name for s in state.messages[start:] for p in s.people if p.name]
        return sum(1 for a, b in itertools.pairwise(shown) if a != b)

    retry_until(lambda: switches() >= 4, 300, 0.2, "four more switches of the face, named")
    wrong = []
    names: list[str] = []
    for s in state.messages:
        for p in s.people:
            if p.name is None or p.yaw_rad is None:
                continue
            names.append(p.name)
            face_is = "Barack" if p.yaw_rad > 0 else "Joe"
            if p.name != face_is:
                wrong.append((s.stamp_ns, p.id, p.name, round(p.yaw_rad, 2)))
    assert names.count("Barack") > 5 and names.count("Joe") > 5, names[-20:]
    assert wrong == [], wrong[:10]
    greeted_by_name(spawn, probe, tmp_path, state)


def face_at(states: list[m.PeopleState]) -> str | None:
    """Whose face the newest of `states` showing one shows (by its direction)."""
    for s in reversed(states):
        for p in s.people:
            if p.yaw_rad is not None and p.seen_by in ("CAMERA", "BOTH"):
                return "Barack" if p.yaw_rad > 0 else "Joe"
    return None


def greeted_by_name(spawn: Callable[..., Process], probe: Node, tmp_path: Path,
                    state: Collector[m.PeopleState]) -> None:
    """Start the real controller (greeting "say:Hello {name}") while the faces go on
    switching; a greeting's name must be the face shown when it was asked for. A
    controller that greeted before a name came is started again (a new greeting:
    no cooldown), up to four times, so a named greeting is checked at least once."""
    asked: list[tuple[str, str | None]] = []  # (the sound, the face shown then)
    goals = itertools.count(1)

    def play(req: m.PlaySound) -> m.PlaySoundReply:
        asked.append((req.sound, face_at(list(state.messages))))
        goal = f"goal-{next(goals)}"
        status.put(m.PlaySoundStatus(goal_id=goal, state="SUCCEEDED", stamp_ns=m.now_ns()))
        return m.PlaySoundReply(goal_id=goal, accepted=True)

    status = probe.publisher(keys.PLAY_SOUND_STATUS)
    probe.publisher(keys.DEVICE_FREE).put(m.Bool(stamp_ns=m.now_ns(), data=True))
    probe.serve(keys.PLAY_SOUND, play)
    config = tmp_path / "controller.toml"
    config.write_text('[controller]\ngreeting_named = "say:Hello {name}"\n'
                      "greet_dwell_s = 0.3\nrecover_s = 0.3\nregreet_cooldown_s = 0.0\n")
    for _attempt in range(4):
        before = len(asked)
        proc = spawn("controller", "--config", str(config))
        retry_until(lambda: len(asked) > before, 60, 0.1, "a greeting")  # noqa: B023
        proc.stop()
        if asked[-1][0].startswith("say:Hello "):
            break
    named = [(sound.removeprefix("say:Hello "), face) for sound, face in asked
             if sound.startswith("say:Hello ")]
    assert named, f"no greeting by name in {asked}"
    assert all(name == face for name, face in named), asked
