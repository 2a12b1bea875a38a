"""`buddybot param set face-detector ...` changes the published face while it runs."""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until
from tests.camera import scenes

pytestmark = pytest.mark.integration


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def face_for(pub: Any, faces: Collector[m.FacePosition], frame: Any, frame_id: str) -> Any:
    img = m.Image(stamp_ns=m.now_ns(), frame_id=frame_id, width=frame.shape[1],
                  height=frame.shape[0], encoding="bgr8", data=frame.tobytes())

    def sent_and_answered() -> Any:
        pub.put(img)
        try:
            return faces.wait_for(lambda f: f.frame_id == frame_id, timeout=0.5)
        except TimeoutError:
            return None

    return retry_until(sent_and_answered, 60, 0.1, f"a face for {frame_id}")


def test_face_width_is_live(spawn: Callable[..., Process], probe: Node, endpoint: str,
                            tmp_path: Path) -> None:
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector[m.FacePosition](probe, keys.FACE, camera="test")
    config = tmp_path / "robot.toml"  # the face width the only distance cue, unsmoothed
    config.write_text("[face_detector]\neye_distance_m = 0.0\nsmoothing = false\n")
    proc = spawn("face-detector", "--camera", "test", "--config", str(config))
    frame, _ = scenes.scene(scenes.grace_hopper(), 1.0, 300, 240)
    before = face_for(pub, faces, frame, "before")
    assert before.point.x == pytest.approx(1.0, rel=0.15)

    result = param(endpoint, "set", "face-detector", "face_width_m", "0.3")
    assert result.returncode == 0, result.stderr
    after = face_for(pub, faces, frame, "after")
    # The same picture, a face taken to be twice as wide: twice as far.
    assert after.point.x == pytest.approx(2 * before.point.x, rel=0.1)
    model = param(endpoint, "set", "face-detector", "model", '"short"')
    assert model.returncode == 1 and "model needs a restart" in model.stderr
    assert proc.alive()
