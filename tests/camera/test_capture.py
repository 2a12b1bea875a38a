"""The camera service (`buddybot run camera`) as a real process through a real router:
image sequences, JPEG and resizing, the end of a file, absent, broken and vanishing
sources, odd pixel formats; and its capture loop in this process fed frames no image
can carry."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from buddybot.camera.capture import Capture
from buddybot.camera.settings import CameraSettings
from buddybot.camera.sources import SourceSpec
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, free_port, retry_until
from tests.camera.jpegs import bgr_of
from tests.camera.mjpeg import MjpegServer

pytestmark = pytest.mark.integration

Spawn = Callable[..., Process]


def write_sequence(folder: Path, n: int, width: int = 64, height: int = 48) -> list[np.ndarray]:
    """PNG frames, each a distinct pattern (value encodes the index)."""
    folder.mkdir(parents=True, exist_ok=True)
    frames = []
    for i in range(n):
        img = np.full((height, width, 3), 10 + 20 * i, np.uint8)
        img[:, : width // 2, 0] = 200 - 10 * i
        cv2.imwrite(str(folder / f"{i:03d}.png"), img)
        frames.append(img)
    return frames


def test_image_sequence_through_the_router(probe: Node, spawn: Spawn, tmp_path: Path) -> None:
    frames = write_sequence(tmp_path / "frames", 8)
    images = Collector(probe, keys.CAMERA_IMAGE, camera="seq")
    proc = spawn("camera", "--source", str(tmp_path / "frames" / "%03d.png"), "--fps", "40",
                 "--camera", "seq", "--loop")

    def all_seen() -> bool:
        got = {bgr_of(msg).tobytes() for msg in images.messages}
        return all(f.tobytes() in got for f in frames)

    retry_until(all_seen, timeout=30, what="all 8 frames of the sequence")
    msgs = images.messages
    assert all(msg.encoding == "bgr8" and (msg.width, msg.height) == (64, 48) for msg in msgs)
    assert all(msg.frame_id == "camera_seq" for msg in msgs)
    stamps = [msg.stamp_ns for msg in msgs]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert abs(stamps[-1] - m.now_ns()) < 30e9
    assert proc.alive()


def test_jpeg_encoding_and_resizing(probe: Node, spawn: Spawn, tmp_path: Path) -> None:
    write_sequence(tmp_path / "frames", 3, 128, 96)
    images = Collector(probe, keys.CAMERA_IMAGE, camera="front")
    spawn("camera", "--source", str(tmp_path / "frames" / "%03d.png"), "--encoding", "jpeg",
          "--width", "64", "--height", "48", "--loop", "--fps", "20")
    msg = images.wait_for(timeout=30, what="a jpeg frame")
    assert msg.encoding == "jpeg" and (msg.width, msg.height) == (64, 48)
    assert bgr_of(msg).shape == (48, 64, 3)


def test_end_of_a_file_ends_the_service_cleanly(spawn: Spawn, tmp_path: Path) -> None:
    write_sequence(tmp_path / "frames", 5)
    proc = spawn("camera", "--source", str(tmp_path / "frames" / "%03d.png"), "--fps", "50")
    retry_until(lambda: not proc.alive(), timeout=60, what="camera exiting at end of input")
    assert proc.proc.returncode == 0
    assert "end of sequence" in proc.output()


@pytest.mark.parametrize("source", ["/nonexistent/clip.mp4", "{tmp}/broken.mp4", "7"])
def test_absent_or_broken_source_is_reported_not_fatal(
    probe: Node, spawn: Spawn, tmp_path: Path, source: str
) -> None:
    (tmp_path / "broken.mp4").write_bytes(b"\x00\x01garbage, not a video" * 100)
    diags = Collector(probe, keys.DIAGNOSTICS, node="camera")
    proc = spawn("camera", "--source", source.format(tmp=tmp_path))
    status = diags.wait_for(
        lambda d: d.level == "ERROR" and int(d.values.get("open_failures", 0)) >= 2,
        timeout=40, what="ERROR diagnostics after two failed opens",
    )
    assert "cannot open" in status.message
    assert proc.alive()


def test_bad_camera_options_are_a_clear_error(spawn: Spawn) -> None:
    proc = spawn("camera", "--sim", "--fps", "-5")
    retry_until(lambda: not proc.alive(), timeout=30, what="camera refusing --fps -5")
    assert proc.proc.returncode == 2
    assert "fps" in proc.output()


def test_network_camera_that_disappears_is_reopened(probe: Node, spawn: Spawn) -> None:
    port = free_port()
    server = MjpegServer(port)
    images = Collector(probe, keys.CAMERA_IMAGE, camera="ipcam")
    diags = Collector(probe, keys.DIAGNOSTICS, node="camera")
    try:
        proc = spawn("camera", "--source", server.url, "--camera", "ipcam")
        images.wait_for(timeout=40, what="a frame from the network camera")
        server.stop()
        diags.wait_for(lambda d: d.level == "ERROR", timeout=60,
                       what="ERROR diagnostics after the camera vanished")
        assert proc.alive()
        images.clear()
        server = MjpegServer(port)
        images.wait_for(timeout=60, what="frames again after the camera came back")
        diags.wait_for(lambda d: d.level == "OK" and int(d.values.get("reopens", 0))
                       + int(d.values.get("open_failures", 0)) >= 1, timeout=30,
                       what="OK diagnostics after reopening")
    finally:
        server.stop()


# --- odd frames ------------------------------------------------------------------------


def write(path: Path, frame: np.ndarray) -> np.ndarray:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), frame)
    return frame


def test_grey_bgra_and_16_bit_files_are_published_as_bgr8(
    probe: Node, spawn: Spawn, tmp_path: Path
) -> None:
    base = np.zeros((48, 64, 3), np.uint8)
    base[:, :32] = (200, 100, 50)
    base[:, 32:] = (20, 60, 240)
    grey = cv2.cvtColor(base, cv2.COLOR_BGR2GRAY)
    folder = tmp_path / "frames"
    write(folder / "000.png", grey)
    write(folder / "001.png", cv2.cvtColor(base, cv2.COLOR_BGR2BGRA))
    write(folder / "002.png", base.astype(np.uint16) * 257)
    write(folder / "003.png", grey.astype(np.uint16) * 257)
    expected = {cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR).tobytes(), base.tobytes()}
    images = Collector(probe, keys.CAMERA_IMAGE, camera="odd")
    diags = Collector(probe, keys.DIAGNOSTICS, node="camera")
    proc = spawn("camera", "--source", str(folder / "%03d.png"), "--camera", "odd",
                 "--fps", "20", "--loop")
    images.wait_count(8, timeout=60)
    msgs = images.messages
    assert all((msg.width, msg.height, msg.encoding) == (64, 48, "bgr8") for msg in msgs)
    assert {msg.data for msg in msgs} == expected
    assert all(int(d.values.get("bad_frames", 0)) == 0 for d in diags.messages)
    assert proc.alive()


class ScriptedSource:
    """A live source delivering the frames of a script, then a good frame forever."""

    def __init__(self, script: list[np.ndarray | None], good: np.ndarray) -> None:
        self.script = list(script)
        self.good = good

    def open(self) -> bool:
        return True

    def read(self) -> np.ndarray | None:
        return self.script.pop(0) if self.script else self.good

    def native_fps(self) -> float | None:
        return None

    def release(self) -> None:
        pass


@pytest.fixture
def capture_node(node_factory: Callable[..., Node]) -> Iterator[Node]:
    yield node_factory("camera")


def test_capture_refuses_unusable_frames_and_keeps_publishing(
    probe: Node, capture_node: Node
) -> None:
    """The capture loop itself (in this process, on the real router) fed by a source
    that delivers frames no Image can carry: each is counted, the next good one goes out."""
    good = np.full((48, 64, 3), 77, np.uint8)
    script: list[np.ndarray | None] = [
        np.zeros((0, 64, 3), np.uint8),  # empty
        np.zeros((48, 64, 2), np.uint8),  # two channels
        np.zeros((48, 64, 3), np.float32),  # float pixels
        np.zeros((2, 16385), np.uint8),  # wider than an Image may be
        np.zeros((1500, 1500, 3), np.uint8),  # 6.75 MB: fits the wire, checked below
        np.zeros((2000, 3000, 3), np.uint8),  # 18 MB of bgr8: above the message limit
    ]
    images = Collector(probe, keys.CAMERA_IMAGE, camera="scripted")
    diags = Collector(probe, keys.DIAGNOSTICS, node="camera")
    settings = CameraSettings(name="scripted", fps=50.0)
    capture = Capture(capture_node, settings, SourceSpec("device", "scripted"),
                      ScriptedSource(script, good))
    runner = threading.Thread(target=capture.run, daemon=True)
    runner.start()
    try:
        images.wait_for(lambda msg: msg.data == good.tobytes(), timeout=60,
                        what="a good frame after the unusable ones")
        capture_node.diagnostics.publish()
        status = diags.wait_for(lambda d: int(d.values.get("bad_frames", 0)) >= 3
                                and int(d.values.get("too_large", 0)) >= 2, timeout=30,
                                what="refused frames counted")
    finally:
        capture_node.stop()
        runner.join(10)
    assert int(status.values["bad_frames"]) == 3 and int(status.values["too_large"]) == 2
    assert not runner.is_alive()
    assert {(msg.width, msg.height) for msg in images.messages} <= {(64, 48), (1500, 1500)}
