"""Recall on hard scenes against MediaPipe's measured recall.

The goal: find at least as many small (3-4 m) and partial
(frame edge) faces as Google MediaPipe 0.10.21 finds on the same frames.
MediaPipe cannot be imported here (it is a benchmark peer in its own
virtualenv), so `benchmarks/faces.py` measured both on the scenes of
`scenes.py`; its figures are written below and in docs/camera.md. Each
family's floor is our measured count minus a small margin (a few faces,
for numerical differences between machines), but for the small-face and
edge families never below MediaPipe's count: where ours is below it, the
test asks for MediaPipe's count and is a strict xfail naming the gap, so it
flips to a failure (remove the mark) the day the detector closes it.

Recall is defined once, in `scenes.matches` / `scenes.found_count`: a true
face is found when a detection overlaps its hand-marked box by IoU >= 0.3
or has its centre inside it; recall = faces found / faces present.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from buddybot.camera.facenet import FaceNet
from buddybot.camera.settings import FaceDetectorSettings
from tests.camera import scenes
from tests.camera.networks import Networks


@dataclass(frozen=True)
class Measured:
    """Faces present, and found by us and by MediaPipe (full range), benchmarks/faces.py."""

    faces: int
    ours: int
    mediapipe: int
    gated: bool
    """Small-face or edge family: at least MediaPipe's recall is asked for."""

    @property
    def floor(self) -> int:
        margin = math.ceil(0.03 * self.faces)
        if self.gated:
            return max(self.ours - margin, self.mediapipe)
        return self.ours - margin


# Whole-frame detection with the service's default model (the sparse full-range
# BlazeFace, fed as MediaPipe feeds it: bilinear scaling, threshold 0.5) vs MediaPipe
# model_selection=1 (min_detection_confidence 0.5); measured 2026-11-23 (figures in
# docs/camera.md).
WHOLE_FRAME = {
    "far": Measured(72, 26, 21, gated=True),
    "small": Measured(72, 56, 47, gated=True),
    "edge25": Measured(48, 23, 19, gated=True),
    "edge50": Measured(48, 5, 1, gated=True),
    "two": Measured(24, 19, 20, gated=False),
    "dark": Measured(36, 26, 25, gated=False),
    "motion": Measured(36, 24, 22, gated=False),
    "defocus": Measured(36, 27, 24, gated=False),
    "jpeg20": Measured(36, 29, 27, gated=False),
}
# The service path (`FacePipeline.process`, crop tracking) over the sequences, frames whose
# published face is the true one, vs MediaPipe full range frame by frame.
SERVICE = {
    "walk": Measured(300, 222, 169, gated=True),
    "leave": Measured(240, 221, 160, gated=True),
}


def _param(family: str, m: Measured) -> object:
    if m.gated and m.ours < m.mediapipe:
        return pytest.param(family, marks=pytest.mark.xfail(strict=True, reason=(
            f"{family}: the default model found {m.ours}/{m.faces}, MediaPipe "
            f"{m.mediapipe}/{m.faces}; at least MediaPipe's recall is asked for")))
    return family


@pytest.fixture(scope="module")
def net(networks: Networks) -> FaceNet:
    """The whole-frame detector the service runs by default."""
    s = FaceDetectorSettings()
    return networks.face(s.model, s.min_score)


def test_match_rule() -> None:
    """The recall rule: IoU >= 0.3, or the detection's centre inside the true box; each
    detection counts for one face only."""
    true = (100.0, 100.0, 130.0, 130.0)
    assert scenes.matches((100, 100, 130, 130), true)
    assert scenes.matches((90, 95, 125, 128), true)  # IoU ~0.54
    assert scenes.matches((60, 60, 180, 180), true)  # IoU 0.06, centre inside
    assert not scenes.matches((125, 125, 165, 165), true)  # corner overlap, centre outside
    assert not scenes.matches((200, 100, 230, 130), true)
    assert scenes.found_count([(100, 100, 130, 130)], (true, true)) == 1
    assert scenes.found_count([], (true,)) == 0


def test_scenes_are_what_they_claim() -> None:
    """The families put faces where their names say (true boxes from the hand-marked
    faces): 20-30 px and 31-60 px wide, 25% and 50% of the box outside the frame, two
    faces; and they are the same on every call (fixed seeds)."""
    widths = [b[2] - b[0] for sc in scenes.far() for b in sc.boxes]
    assert min(widths) >= 19.0 and max(widths) <= 31.0
    widths = [b[2] - b[0] for sc in scenes.small() for b in sc.boxes]
    assert min(widths) >= 30.0 and max(widths) <= 60.0
    for build, fraction in ((scenes.edge25, 0.25), (scenes.edge50, 0.5)):
        for sc in build():
            (x0, y0, x1, y1), = sc.boxes
            sideways = " left " in sc.name or " right " in sc.name
            outside = (max(-x0, x1 - scenes.WIDTH) / (x1 - x0) if sideways
                       else max(-y0, y1 - scenes.HEIGHT) / (y1 - y0))
            assert outside == pytest.approx(fraction, abs=0.01), sc.name
    assert all(len(sc.boxes) == 2 for sc in scenes.two())
    a, b = scenes.two(), scenes.two()
    assert all(np.array_equal(x.bgr, y.bgr) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("family", [_param(f, m) for f, m in WHOLE_FRAME.items()])
def test_whole_frame_recall(net: FaceNet, family: str) -> None:
    """`FaceNet.detect` on the whole frame finds at least the family's floor."""
    m = WHOLE_FRAME[family]
    found = present = 0
    for sc in scenes.FAMILIES[family]():
        present += len(sc.boxes)
        found += scenes.found_count([d.box for d in net.detect(sc.bgr)], sc.boxes)
    assert present == m.faces
    print(f"{family}: {found}/{present} (floor {m.floor}, MediaPipe {m.mediapipe})")
    assert found >= m.floor, (f"{family}: found {found}/{present}, floor {m.floor} "
                              f"(measured {m.ours}, MediaPipe {m.mediapipe})")


@pytest.mark.parametrize("kind", [_param(k, m) for k, m in SERVICE.items()])
def test_service_path_recall(kind: str, networks: Networks) -> None:
    """The service path over sequences (a walk 0.6-4 m and back; faces leaving by each
    edge): frames whose published face is the true face reach the floor, and no frame
    publishes a face anywhere else (there is one person). A fresh pipeline per sequence,
    frames 33 ms apart as from a 30 fps camera."""
    m = SERVICE[kind]
    found = frames = 0
    wrong: list[str] = []
    for seq in scenes.sequences(kind):
        pipe = scenes.service_pipeline(net=networks.face(FaceDetectorSettings().model,
                                                         FaceDetectorSettings().min_score))
        for i, (img, true) in enumerate(seq):
            box = scenes.published_box(pipe.process(img, (i + 1) * 33_333_333))
            if box is not None:
                if scenes.matches(box, true):
                    found += 1
                else:
                    wrong.append(f"{seq.name} frame {i}")
            frames += 1
    assert frames == m.faces
    assert not wrong, f"published a face where there is none: {wrong}"
    print(f"{kind}: {found}/{frames} (floor {m.floor}, MediaPipe {m.mediapipe})")
    assert found >= m.floor, (f"{kind}: {found}/{frames} frames, floor {m.floor} "
                              f"(measured {m.ours}, MediaPipe {m.mediapipe})")
