"""Faults and attacks on the camera services, through a real router.

A JPEG bomb, wrong clocks and odd frames sent to real `face-detector` and
`camera` processes: each is refused or converted and counted, memory stays
bounded, and the services keep answering normal frames of a real face.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import psutil
import pytest

from buddybot.camera.capture import Capture
from buddybot.camera.settings import CameraSettings
from buddybot.camera.sources import SourceSpec
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.limits import stamp_plausible
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, retry_until
from tests.camera import jpegs, scenes

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
    for n, img in enumerate(bad, 1):
        pub.put(img)
        diags.wait_for(lambda d, n=n: int(d.values.get("bad_frames", 0)) >= n, timeout=60,
                       what=f"{n} bad frames counted")
    # A huge frame_id (it would be copied into every face message) is refused at decode.
    pub.put(image(frame, m.now_ns(), "x" * 1_000_000))
    diags.wait_for(lambda d: int(d.values.get("malformed", 0)) >= 1, timeout=60,
                   what="the huge frame_id refused")
    # Above --max-pixels (here 1 MP): refused before decoding, by message or by header.
    big = np.zeros((1000, 1001, 3), np.uint8)
    pub.put(image(big, m.now_ns(), "big", "jpeg"))
    diags.wait_for(lambda d: int(d.values.get("too_large", 0)) >= 1, timeout=60,
                   what="a frame above max_pixels counted")
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


# --- capture side ------------------------------------------------------------------------


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


def test_a_face_jump_is_never_published_at_a_wrong_distance(probe: Node, spawn: Spawn) -> None:
    """The jump of test_jump.py through a running detector (crop tracking and smoothing
    as in service): a face 90 px wide at the upper left (1.0 m), then 150 px at the lower
    right (0.6 m). Every published distance within 15% of the truth, and the new face
    published for the first two frames after the jump (not held back as a bystander)."""
    pub = probe.publisher(keys.CAMERA_IMAGE, camera="test")
    faces = Collector(probe, keys.FACE, camera="test")
    proc = spawn("face-detector", "--camera", "test")
    before, _ = scenes.scene(scenes.astronaut(), 1.0, 130, 120)
    after, placed = scenes.scene(scenes.astronaut(), 0.6, 470, 330)
    answer(pub, faces, image(before, m.now_ns(), "warm-up"))
    base = m.now_ns()  # camera stamps 33 ms apart from here (plausible: behind arrival)
    for i in range(8):
        face = answer(pub, faces, image(before, base + i * 33_333_333, f"before-{i}"))
        assert face.point.x == pytest.approx(1.0, rel=0.15)
    published: list[float | None] = []
    for i in range(8, 16):
        pub.put(image(after, base + i * 33_333_333, f"after-{i}"))
        try:
            face = faces.wait_for(lambda f, i=i: f.frame_id == f"after-{i}", timeout=5.0)
            published.append(face.point.x)
        except TimeoutError:
            published.append(None)
    print(f"published after the jump (true {placed.z_m} m): {published}")
    assert published[0] is not None and published[1] is not None, published
    assert all(abs(x - placed.z_m) <= 0.15 * placed.z_m for x in published if x is not None)
    assert proc.alive()
