"""The whole robot as separate processes on a test router, for system tests.

Radar frames go through a real pty (the bridge's simulated LD2410), camera
images come from an image sequence of a real face photo composed at known
places, sound plays on miniaudio's null device, the eye renderer serves
its page without a browser.
"""

from __future__ import annotations

import bisect
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from buddybot.camera.sim import compose, face_path
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.runtime.registry import available_services
from buddybot.tools.testing import (
    Process,
    buddybot_argv,
    free_port,
    retry_until,
    write_tone,
)
from tests.sim import SCENARIOS

Spawn = Callable[..., Process]

# Everything but the radar bridge, which starts last so its scripted visitor
# walks in only once the robot is listening.
BASE_SERVICES: dict[str, tuple[str, ...]] = {
    "audio-player": ("--backend", "null"),
    "audio": (),
    "eyes": (),
    "controller": (),
    "people": (),  # the controller's presence: radar/presence -> people/state
    "face-detector": (),
    "radar-presence": (),
}


def write_face_sequence(folder: Path, n: int = 40) -> str:
    """Frames of one face (1 m away, fx 600): first half image-left, then image-right.

    Image-left is the camera's (and the robot's) left, so the eyes must turn
    to +yaw for the first half and -yaw for the second.
    """
    folder.mkdir(parents=True, exist_ok=True)
    face = cv2.imread(str(face_path()), cv2.IMREAD_COLOR)
    assert face is not None
    rng = np.random.default_rng(1)
    for i in range(n):
        background = rng.integers(70, 110, (480, 640, 3), dtype=np.uint8)
        u = 190 if i < n // 2 else 450
        frame = compose(background, face, None, u, 220, 240)
        cv2.imwrite(str(folder / f"{i:04d}.png"), frame)
    return str(folder / "%04d.png")


GREETING_S, FAREWELL_S = 0.6, 1.2


def write_config(folder: Path) -> Path:
    """A robot config whose greeting and farewell differ in length (told apart in tests)."""
    folder.mkdir(parents=True, exist_ok=True)
    write_tone(folder / "hello.wav", GREETING_S, 660, rate=16000)
    write_tone(folder / "bye.wav", FAREWELL_S, 440, rate=16000)
    path = folder / "robot.toml"
    # Without the alert face and the alone phase: these tests compare expression
    # sequences across runs and restarts (test_alive.py has the defaults).
    path.write_text('[audio.sounds]\ngreeting = "hello.wav"\nfarewell = "bye.wav"\n'
                    '[controller]\nalert_s = 0.0\nalone_s = 0.0\n')
    return path


def start_robot(spawn: Spawn, tmp_path: Path, *, robot: str = "buddy", fps: int = 15,
                renderer: bool = False, camera: bool = True,
                services: dict[str, tuple[str, ...]] | None = None) -> dict[str, Process]:
    """Start every service but the radar bridge (see `start_radar`); the camera
    plays a face sequence unless `camera` is false (see `start_world`)."""
    chosen = dict(BASE_SERVICES if services is None else services)
    config = write_config(tmp_path / "config")
    if camera:
        pattern = write_face_sequence(tmp_path / "frames")
        chosen["camera"] = ("--source", pattern, "--fps", str(fps), "--loop")
    if renderer:
        chosen["eye-renderer"] = ("--no-browser", "--port", str(free_port()))
    return {name: spawn(name, "--config", str(config), *args, robot=robot)
            for name, args in chosen.items()}


def wait_nodes(probe: Node, names: list[str], robot: str = "buddy",
               timeout: float = 60.0) -> None:
    def all_up() -> bool:
        live = probe.node_instances(all_robots=True)
        return all(f"{robot}/{name}" in live for name in names)

    retry_until(all_up, timeout, 0.3, f"nodes {names} up")


def scenario_arg(name: str) -> str:
    """A built-in scenario name, or the path of the tests' scenario of that name."""
    own = SCENARIOS / f"{name}.toml"
    return str(own) if own.exists() else name


def start_world(spawn: Spawn, scenario: str, config: Path, robot: str = "buddy",
                fps: int = 15, lead_s: float = 3.0) -> dict[str, Process]:
    """The radar bridge's simulated LD2410 and the camera filming one simulated
    world, from one wall-clock start `lead_s` ahead (as `up --sim` starts them),
    so the person the radar sees is the face the camera shows."""
    start = f"{time.time() + lead_s:.3f}"
    world = ("--sim", "--scenario", scenario_arg(scenario), "--sim-start", start)
    return {"radar-bridge": spawn("radar-bridge", *world, robot=robot),
            "camera": spawn("camera", "--config", str(config), *world, "--fps", str(fps),
                            robot=robot)}


def start_radar(spawn: Spawn, scenario: str, robot: str = "buddy",
                speed: float = 1.0) -> Process:
    """The bridge with its simulated LD2410 seeing `scenario`, started now."""
    return spawn("radar-bridge", "--sim", "--scenario", scenario_arg(scenario),
                 "--sim-speed", str(speed), robot=robot)


@contextmanager
def up_sim(tmp_path: Path, config_text: str = "", args: tuple[str, ...] = (),
           nodes: int | None = None) -> Iterator[tuple[Process, Node, str]]:
    """`buddybot up --sim` on private ports (sound on the null device, the camera at 15
    fps, `config_text` after it, `args` added), waited for until its `nodes` (default:
    every service `up` starts) are up; the process, a probe on its router and its
    endpoint."""
    config = tmp_path / "robot.toml"
    # These tests check behaviour, not frame rates: at 15 frames a second the robot
    # takes 27 % of a core instead of 38 % at 30 (the face detector is most of it).
    config.write_text('[audio_player]\nbackend = "null"\n[camera]\nfps = 15\n' + config_text)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    up = Process(buddybot_argv("up", "--sim", "--no-browser", "--listen", endpoint,
                               "--config", str(config), "--eye-port", str(free_port()),
                               "--dashboard-port", str(free_port()), "--status-period", "1",
                               *args), "up", tmp_path / "logs")
    probe: Node | None = None
    try:
        n = nodes if nodes is not None else len(
            [e for e in available_services() if not e.on_request])
        up.wait_for_output(f"nodes {n}/{n}", 180)
        probe = Node("probe", robot="buddy", connect=[endpoint], probe=True)
        yield up, probe, endpoint
    finally:
        if probe is not None:
            probe.close()
        status = up.stop(30)
        print(up.output()[-6000:])
        assert status == 0


@contextmanager
def robot_on(tmp_path: Path, scenario: str, config_text: str = "") -> Iterator[Node]:
    """`buddybot up --sim --scenario` (`up_sim`); a probe on its router."""
    with up_sim(tmp_path, config_text, ("--scenario", scenario)) as (_up, probe, _endpoint):
        yield probe


def sounds(states: list[m.ControllerState]) -> list[str]:
    """Each sound of ours, once, in the order it started."""
    out: list[str] = []
    for prev, cur in zip([None, *states], states, strict=False):
        if cur.sound and (prev is None or prev.sound != cur.sound):
            out.append(cur.sound)
    return out


class Arrivals:
    """Every message of one topic with when it arrived (monotonic s): what was in
    effect at an instant, whatever the publishers' stamps say."""

    def __init__(self, node: Node, topic: keys.Topic) -> None:
        self.at: list[float] = []
        self.messages: list[Any] = []
        self._lock = threading.Lock()
        node.subscribe(topic, self._on)

    def _on(self, msg: Any, _key: str) -> None:
        with self._lock:
            self.at.append(time.monotonic())
            self.messages.append(msg)

    def in_effect(self, t: float) -> Any | None:
        with self._lock:
            i = bisect.bisect_right(self.at, t)
            return self.messages[i - 1] if i else None
