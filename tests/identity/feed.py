"""Real photos fed to the bus as the camera and the face detector publish them.

`scene(photo)` is a photo as the camera's JPEG plus the followed face the
project's own detector finds in it (box, BlazeFace keypoints); `Camera`
publishes the current scene on a thread, image first, then its faces with
the same stamp, as `camera` and `face-detector` do. Used by
tests/identity/test_service.py and benchmarks/identity_service.py.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import cv2

from buddybot.camera.facenet import FaceNet
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from tests.identity.photos import Photo, detection


@dataclass(frozen=True)
class Scene:
    """One photo as the camera's jpeg and the detector's followed face."""

    jpeg: bytes
    width: int
    height: int
    face: m.FaceBox


def scene(nets: tuple[FaceNet, FaceNet], p: Photo) -> Scene:
    det = detection(nets, p.bgr)
    ok, data = cv2.imencode(".jpg", p.bgr, [cv2.IMWRITE_JPEG_QUALITY, 95])
    assert ok
    h, w = p.bgr.shape[:2]
    x0, y0, x1, y1 = (float(v) for v in det.box)
    return Scene(data.tobytes(), w, h, m.FaceBox(
        x0=max(0.0, x0), y0=max(0.0, y0), x1=x1, y1=y1, score=min(1.0, det.score),
        keypoints=[m.PixelPoint(x=float(x), y=float(y)) for x, y in det.keypoints],
        followed=True))


class Camera:
    """Publishes the current scene every `period_s` on a thread: image, then its faces.

    `faces` > 1 adds look-alike boxes (an enrolment must refuse them);
    `sent` holds the stamps of the frames with a face since the last `show`.
    """

    def __init__(self, probe: Node, period_s: float = 0.05, camera: str = "front") -> None:
        self.image_pub = probe.publisher(keys.CAMERA_IMAGE, camera=camera)
        self.faces_pub = probe.publisher(keys.FACES, camera=camera)
        self.period_s = period_s
        self.scene: Scene | None = None
        self.faces = 1
        self.sent: list[int] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def show(self, shown: Scene | None, faces: int = 1) -> None:
        with self._lock:
            self.scene, self.faces, self.sent = shown, faces, []

    def frames_until(self, stamp_ns: int) -> int:
        """Frames with a face sent since `show`, up to and including `stamp_ns`."""
        with self._lock:
            return sum(1 for s in self.sent if s <= stamp_ns)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            with self._lock:
                shown, count = self.scene, self.faces
                stamp = m.now_ns()
                if shown is not None:
                    self.sent.append(stamp)
            if shown is None:
                self.faces_pub.put(m.FaceDetections(stamp_ns=stamp, frame_id="front",
                                                    width=640, height=480))
                continue
            self.image_pub.put(m.Image(stamp_ns=stamp, frame_id="front", width=shown.width,
                                       height=shown.height, encoding="jpeg", data=shown.jpeg))
            other = m.FaceBox(x0=0.0, y0=0.0, x1=10.0, y1=10.0, score=0.9,
                              keypoints=shown.face.keypoints)
            self.faces_pub.put(m.FaceDetections(
                stamp_ns=stamp, frame_id="front", width=shown.width, height=shown.height,
                faces=[shown.face] + [other] * (count - 1)))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
