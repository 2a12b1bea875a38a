"""The iris stage inside the face pipeline: measured when due, held, reset, and used.

Real inference on composed photos (scenes.py). The iris and fusion maths
have their own tests (test_iris.py, test_fusion.py); these check the wiring:
that the pipeline measures at the right moments, that what it learns reaches
the published distance, and that it forgets it for a new person.
"""

from __future__ import annotations

import cv2
import msgspec
import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import draw, fusion, models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.iris import IrisNet
from buddybot.camera.pipeline import FacePipeline, OwedIris
from buddybot.camera.settings import FaceDetectorSettings
from tests.camera import scenes

FX = 600.0


@pytest.fixture(scope="module")
def parts() -> tuple[FaceNet, FaceNet, IrisNet]:
    cv2.setNumThreads(1)
    return (FaceNet(models.locate("full_sparse"), bf.FULL_SPARSE),
            FaceNet(models.locate("short"), bf.SHORT_RANGE), IrisNet())


def pipeline(parts: tuple[FaceNet, FaceNet, IrisNet], iris: bool = True,
             **changes: object) -> FacePipeline:
    settings = msgspec.structs.replace(FaceDetectorSettings(), fx=FX, fy=FX, iris=iris,
                                       **changes)
    net, refiner, irises = parts
    return FacePipeline(net, settings, refiner, irises=irises if iris else None)


def frames_at(photo: scenes.Photo, z: float, count: int, u: float = 320.0,
              v: float = 240.0) -> list[np.ndarray]:
    return [scenes.scene(photo, z, u, v, FX, seed=i)[0] for i in range(count)]


def run(p: FacePipeline, imgs: list[np.ndarray], start_s: float = 100.0,
        period_s: float = 1 / 30) -> list[object]:
    return [p.process(img, round((start_s + i * period_s) * 1e9)) for i, img in enumerate(imgs)]


def test_a_close_face_is_measured_every_iris_every_s_and_the_iris_is_used(parts) -> None:
    p = pipeline(parts, iris_every_s=0.5)
    results = run(p, frames_at(scenes.astronaut(), 0.4, 31))  # one second at 30 fps
    assert p.iris_measurements == 3  # at 0, 0.5 and 1.0 s
    assert p.iris_accepted >= 2
    last = results[-1].estimate
    assert last is not None and last.fusion is not None
    assert fusion.IRIS_HELD in last.fusion.used
    assert last.fusion.weight(fusion.IRIS_HELD) > 0.2
    assert last.z_m == pytest.approx(0.4, rel=0.05)
    assert fusion.IRIS_HELD in last.fusion.summary()


def test_iris_off_means_no_measurement_and_no_iris_cue(parts) -> None:
    p = pipeline(parts, iris=False)
    results = run(p, frames_at(scenes.astronaut(), 0.4, 10))
    assert p.iris_measurements == 0
    last = results[-1].estimate
    assert last is not None and last.fusion is not None
    assert set(last.fusion.used) == {fusion.WIDTH, fusion.EYES}


def test_a_far_face_is_not_measured(parts) -> None:
    """At 2 m the iris is ~3.5 px: the stage would cost 6 ms for nothing."""
    p = pipeline(parts)
    run(p, frames_at(scenes.astronaut(), 2.0, 20))
    assert p.iris_measurements == 0


def test_deferred_processing_measures_only_after_publishing(parts) -> None:
    p = pipeline(parts)
    img = frames_at(scenes.astronaut(), 0.4, 1)[0]
    first = p.process(img, 100_000_000_000, defer=True)
    assert first.target is not None and p.iris_measurements == 0
    [owed] = first.owed
    assert isinstance(owed, OwedIris) and owed.measured is first.measured
    assert p.run_owed(first.owed) is None  # no whole-frame pass was owed
    assert p.iris_measurements == 1
    second = p.process(img, 100_033_000_000, defer=True)  # within iris_every_s: not owed
    assert not any(isinstance(work, OwedIris) for work in second.owed)


def test_a_new_person_is_not_measured_with_the_last_ones_iris(parts) -> None:
    """The held ratio belongs to one person: after a switch it must be learnt again."""
    p = pipeline(parts, iris_every_s=10.0)
    run(p, frames_at(scenes.astronaut(), 0.6, 3, u=470.0))
    first = p.iris_held.ipd_m
    assert first is not None
    # Nobody for a while, then somebody else, elsewhere in the frame (more than a
    # box width away: the tracker takes a face near the old place for the same person).
    empty = [scenes.background(seed=7)] * 30
    run(p, empty, start_s=101.0)
    hopper = frames_at(scenes.grace_hopper(), 0.5, 1, u=140.0, v=220.0)
    result = p.process(hopper[0], 103_000_000_000)
    assert result.target is not None
    # Measured at once for the newcomer (schedule reset) and from their own eyes.
    assert p.iris_measurements == 2
    second = p.iris_held.ipd_m
    # Her own eye distance (~68.6 mm on this photo), not a blend with the astronaut's (~62.6).
    assert second is not None and abs(second - first) > 0.003


def test_the_debug_image_names_the_cues(parts) -> None:
    p = pipeline(parts)
    imgs = frames_at(scenes.astronaut(), 0.4, 2)
    results = run(p, imgs)
    last = results[-1]
    plain = draw.render(imgs[-1], last.faces, last.target, None, last.measured)
    named = draw.render(imgs[-1], last.faces, last.target, last.estimate, last.measured)
    bottom = slice(imgs[-1].shape[0] - 30, imgs[-1].shape[0])
    assert np.any(plain[bottom] != named[bottom])  # the summary line is drawn there
