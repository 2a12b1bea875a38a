"""`camera/<cam>/faces`: a processed frame as FaceDetections (pure, no processes).

Every message is sent through the topic's own codec and decoded with
validation, as a viewer or the recorder would: a value outside its field's
range fails the test, not a receiver.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from buddybot.camera import blazeface as bf
from buddybot.camera import detections, fusion
from buddybot.camera.facenet import FaceNet
from buddybot.camera.geometry import DistanceEstimate, Intrinsics, locate
from buddybot.camera.pipeline import FacePipeline, FaceResult
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.contract import keys
from buddybot.contract import messages as m
from tests.camera import scenes
from tests.camera.networks import Networks

STAMP = 1_700_000_000_000_000_000


def received(msg: m.FaceDetections) -> m.FaceDetections:
    """What a subscriber of `camera/<cam>/faces` decodes (ranges checked)."""
    topic = keys.FACES
    decoded: m.FaceDetections = topic.codec.decode(topic.codec.encode(msg), topic.type)
    return decoded


def det(x0: float, y0: float, w: float, score: float = 0.9) -> bf.Detection:
    """A frontal face box with plausible keypoints (eyes a third of the width apart)."""
    kp = np.array([[x0 + 0.33 * w, y0 + 0.35 * w], [x0 + 0.67 * w, y0 + 0.35 * w],
                   [x0 + 0.5 * w, y0 + 0.55 * w], [x0 + 0.5 * w, y0 + 0.75 * w],
                   [x0 + 0.05 * w, y0 + 0.4 * w], [x0 + 0.95 * w, y0 + 0.4 * w]], np.float32)
    return bf.Detection((x0, y0, x0 + w, y0 + w), score, kp)


K = Intrinsics.resolve(640, 480, fx=600.0)


def followed(faces: list[bf.Detection], target: bf.Detection,
             measured: bf.Detection | None = None, tracked: bool = False) -> FaceResult:
    """A result following `target` (measured as `measured`), geometry as the pipeline's."""
    where = locate(measured or target, K, 0.15, 0.063)
    return FaceResult(faces, target, where.estimate, where.point, where.point, measured,
                      tracked=tracked)


@pytest.fixture(scope="module")
def nets(networks: Networks) -> tuple[FaceNet, FaceNet]:
    return networks.face("full_sparse"), networks.face("short")


def test_a_real_frame_gives_its_face_with_keypoints_distance_and_cues(
    nets: tuple[FaceNet, FaceNet]
) -> None:
    pipe = FacePipeline(nets[0], FaceDetectorSettings(smoothing=False, full_every_s=0.25),
                        nets[1])
    frame, placed = scenes.scene(scenes.astronaut(), 1.0, 300, 240)
    first = pipe.process(frame, STAMP, defer=True)
    second = pipe.process(frame, STAMP + 33_000_000, defer=True)
    assert first.estimate is not None and first.estimate.fusion is not None
    msg = received(detections.to_message(first, STAMP, "front", 640, 480))

    assert (msg.stamp_ns, msg.frame_id, msg.width, msg.height) == (STAMP, "front", 640, 480)
    assert len(msg.faces) == 1 and not msg.tracked
    face = msg.faces[0]
    assert face.followed and face.score > 0.7 and len(face.keypoints) == 6
    assert face.x0 < placed.u < face.x1 and face.y0 < placed.v < face.y1
    right, left = face.keypoints[bf.RIGHT_EYE], face.keypoints[bf.LEFT_EYE]
    assert right.x < placed.u < left.x  # the subject's right eye is on the image's left
    assert msg.distance_m == pytest.approx(first.estimate.z_m)  # before smoothing
    assert abs(msg.distance_m - 1.0) < 0.1
    assert [c.name for c in msg.cues] == [c.name for c in first.estimate.fusion.cues]
    used = [c for c in msg.cues if c.status == fusion.USED]
    assert used and math.isclose(sum(c.weight for c in used), 1.0, rel_tol=1e-6)
    # The next frame comes from the crop track: said so, the face still followed.
    again = received(detections.to_message(second, STAMP + 33_000_000, "front", 640, 480))
    assert again.tracked and second.tracked and again.faces[0].followed


def test_a_frame_without_a_face_is_an_empty_message(nets: tuple[FaceNet, FaceNet]) -> None:
    pipe = FacePipeline(nets[0], FaceDetectorSettings(smoothing=False), nets[1])
    result = pipe.process(scenes.background(), STAMP)
    msg = received(detections.to_message(result, STAMP, "front", 640, 480))
    assert msg.faces == [] and msg.distance_m is None and msg.cues == [] and not msg.tracked


def test_only_the_followed_face_is_marked_and_shown_as_measured() -> None:
    left, right, far = det(50, 100, 120), det(400, 120, 100), det(560, 40, 30, 0.6)
    refined = det(52, 98, 118, 0.97)
    msg = received(detections.to_message(followed([left, right, far], right, refined),
                                         STAMP, "front", 640, 480))
    assert [f.followed for f in msg.faces] == [False, True, False]
    assert msg.faces[1].x0 == pytest.approx(52) and msg.faces[1].score == pytest.approx(0.97)
    assert msg.faces[0].x0 == pytest.approx(50) and msg.faces[2].score == pytest.approx(0.6)
    assert msg.distance_m is not None and msg.cues


def test_faces_without_a_followed_one_have_no_distance() -> None:
    # Bystanders seen while the followed person is briefly away: boxes, no distance.
    faces = [det(50, 100, 120), det(400, 120, 100)]
    estimate = locate(faces[0], K, 0.15, 0.063).estimate
    result = FaceResult(faces, None, estimate, None, None, None)
    msg = received(detections.to_message(result, STAMP, "front", 640, 480))
    assert [f.followed for f in msg.faces] == [False, False]
    assert msg.distance_m is None and msg.cues == []


def test_a_followed_face_missing_from_the_list_is_still_shown() -> None:
    target = det(200, 100, 100)
    msg = received(detections.to_message(followed([det(10, 10, 50)], target), STAMP, "f",
                                         640, 480))
    assert [f.followed for f in msg.faces] == [False, True]


def test_more_faces_than_the_message_holds_keep_the_followed_one() -> None:
    crowd = [det(float(i), 0.0, 10.0) for i in range(detections.MAX_FACES + 10)]
    target = crowd[-1]
    msg = received(detections.to_message(followed(crowd, target), STAMP, "front", 640, 480))
    assert len(msg.faces) == detections.MAX_FACES
    assert sum(f.followed for f in msg.faces) == 1


def test_strange_values_are_put_into_range_never_raised() -> None:
    nan, inf = math.nan, math.inf
    kp = np.array([[nan, 1.0], [inf, -inf], [1e12, -1e12], [5.0, 6.0], [7.0, 8.0],
                   [9.0, 10.0], [11.0, 12.0]], np.float64)  # one keypoint too many
    weird = bf.Detection((nan, -inf, inf, 1e9), 1.7, kp)
    negative = bf.Detection((1.0, 2.0, 3.0, 4.0), -0.2, np.zeros((3,), np.float32))
    cues = (fusion.Weighted("width", inf, 10.0, 0.1, 1.7, fusion.USED),
            fusion.Weighted("eyes", -3.0, 0.0, inf, nan, fusion.INVALID),
            fusion.Weighted("iris_held" * 10, 5000.0, 4.0, 0.1, 0.5, "too small" * 20))
    estimate = DistanceEstimate(nan, inf, None, 0.0, fusion.Fusion(nan, nan, cues * 3))
    result = FaceResult([weird, negative], weird, estimate, None, None, None)

    msg = received(detections.to_message(result, -5, "x" * 1000, 0, 10**9))
    first, second = msg.faces
    assert (first.x0, first.y0, first.x1, first.y1) == (0.0, 0.0, 0.0, detections.PX_MAX)
    assert first.score == 1.0 and second.score == 0.0 and first.followed
    assert [(p.x, p.y) for p in first.keypoints[:3]] == [
        (0.0, 1.0), (0.0, 0.0), (detections.PX_MAX, detections.PX_MIN)]
    assert len(first.keypoints) == detections.MAX_KEYPOINTS
    assert [(p.x, p.y) for p in second.keypoints] == [(0.0, 0.0)]  # 3 values: one pair
    assert msg.distance_m is None
    assert len(msg.cues) == detections.MAX_CUES
    width_cue, eyes_cue, iris_cue = msg.cues[:3]
    assert (width_cue.distance_m, width_cue.weight) == (None, 1.0)
    assert (eyes_cue.distance_m, eyes_cue.weight, eyes_cue.status) == (0.0, 0.0, "invalid")
    assert iris_cue.distance_m == detections.M_MAX
    assert len(iris_cue.name) == detections.NAME_MAX
    assert len(iris_cue.status) == detections.STATUS_MAX
    assert (msg.stamp_ns, msg.width, msg.height) == (0, 1, detections.SIDE_MAX)
    assert len(msg.frame_id) == detections.FRAME_ID_MAX



def test_bystanders_of_the_last_whole_frame_pass_show_on_tracked_frames() -> None:
    """Tracked frames hold only the followed face: the others come from the last
    whole-frame pass, not the followed one twice, and only for `hold_s`."""
    you, other = det(50, 100, 120), det(400, 120, 100)
    searched = followed([you, other], you)
    keeper = detections.Bystanders()
    keeper.update([you, other], searched, STAMP)
    tracked = followed([you], you, tracked=True)
    shown = keeper.current(tracked, STAMP + 100_000_000, hold_s=0.6)
    assert shown == [other]
    msg = received(detections.to_message(tracked, STAMP, "front", 640, 480, shown))
    assert [(f.followed, round(f.x0)) for f in msg.faces] == [(True, 50), (False, 400)]
    assert keeper.current(tracked, STAMP + 700_000_000, hold_s=0.6) == []  # too old
    assert keeper.current(followed([you], you), STAMP + 1, hold_s=0.6) == []  # own faces
