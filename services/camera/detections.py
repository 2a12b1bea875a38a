"""One processed frame as `FaceDetections`: every face in image pixels, for viewers.

The dashboard, the Foxglove bridge and recordings draw the boxes themselves
from this message instead of decoding the debug JPEG. Pure and cheap (it
runs on the detector's frame thread, right after the face is published):
plain floats, no NumPy per value.

A strange detection (a NaN keypoint, an infinite distance, a box far
outside the image) must never raise here nor make receivers refuse the
message, so every value is put into its field's range: a non-finite pixel
or weight becomes 0, a non-finite distance None, anything else is clamped.
The ranges are read from the message types once (`contract/messages.py` is
their one definition).
"""

from __future__ import annotations

import math

import msgspec
import msgspec.inspect as mi

from buddybot.camera import blazeface as bf
from buddybot.camera.fusion import Weighted
from buddybot.camera.pipeline import FaceResult
from buddybot.contract import messages as m
from buddybot.runtime.overrides import field_info


def _constraint(struct: type[msgspec.Struct], field: str, name: str) -> float:
    """A bound (`ge`, `le`, `max_length`) of a message field, also inside `X | None`."""
    t = field_info(struct, field).type
    if isinstance(t, mi.UnionType):
        t = next(u for u in t.types if not isinstance(u, mi.NoneType))
    if isinstance(t, mi.Metadata):
        t = t.type
    value = getattr(t, name)
    assert value is not None, f"{struct.__name__}.{field} has no {name}"
    return float(value)


PX_MIN = _constraint(m.PixelPoint, "x", "ge")
PX_MAX = _constraint(m.PixelPoint, "x", "le")
M_MAX = _constraint(m.DistanceCue, "distance_m", "le")
SIDE_MAX = int(_constraint(m.FaceDetections, "width", "le"))
MAX_FACES = int(_constraint(m.FaceDetections, "faces", "max_length"))
MAX_KEYPOINTS = int(_constraint(m.FaceBox, "keypoints", "max_length"))
MAX_CUES = int(_constraint(m.FaceDetections, "cues", "max_length"))
NAME_MAX = int(_constraint(m.DistanceCue, "name", "max_length"))
STATUS_MAX = int(_constraint(m.DistanceCue, "status", "max_length"))
FRAME_ID_MAX = int(_constraint(m.FaceDetections, "frame_id", "max_length"))


def _px(v: float) -> float:
    """An image coordinate in the Pixel range (non-finite: 0)."""
    if not math.isfinite(v):
        return 0.0
    return PX_MIN if v < PX_MIN else PX_MAX if v > PX_MAX else v


def _unit(v: float) -> float:
    """A score or weight in 0..1 (non-finite: 0)."""
    if not math.isfinite(v):
        return 0.0
    return 0.0 if v < 0.0 else 1.0 if v > 1.0 else v


def _metres(v: float | None) -> float | None:
    """A distance in 0..M_MAX, or None when there is no finite one."""
    if v is None or not math.isfinite(v):
        return None
    return 0.0 if v < 0.0 else M_MAX if v > M_MAX else v


def face_box(det: bf.Detection, followed: bool = False) -> m.FaceBox:
    """One detection as a FaceBox (at most MAX_KEYPOINTS keypoints)."""
    x0, y0, x1, y1 = (float(v) for v in det.box)
    # One conversion to plain floats; any shape gives (x, y) pairs, never an error.
    flat = det.keypoints.ravel().tolist()[:2 * MAX_KEYPOINTS]
    return m.FaceBox(
        x0=_px(x0), y0=_px(y0), x1=_px(x1), y1=_px(y1), score=_unit(float(det.score)),
        keypoints=[m.PixelPoint(x=_px(x), y=_px(y))
                   for x, y in zip(flat[::2], flat[1::2], strict=False)],
        followed=followed,
    )


def distance_cue(cue: Weighted) -> m.DistanceCue:
    """One fusion record entry as a DistanceCue."""
    return m.DistanceCue(name=cue.name[:NAME_MAX], distance_m=_metres(cue.z_m),
                         weight=_unit(cue.weight), status=cue.status[:STATUS_MAX])


def _boxes(result: FaceResult, others: list[bf.Detection]) -> list[m.FaceBox]:
    """Every face; the followed one as measured (refined), as the debug image draws it.

    When there are more faces than the message holds, the followed one is kept.
    """
    target = result.target
    followed = None if target is None else (
        result.measured if result.measured is not None else target)
    boxes: list[m.FaceBox] = []
    found = False
    for det in result.faces:
        if target is not None and det is target:
            assert followed is not None
            boxes.append(face_box(followed, followed=True))
            found = True
        else:
            boxes.append(face_box(det))
    if followed is not None and not found:  # not among the faces: still show it
        boxes.append(face_box(followed, followed=True))
    boxes.extend(face_box(det) for det in others if det not in result.faces)
    if len(boxes) > MAX_FACES:
        boxes.sort(key=lambda b: not b.followed)  # stable: the followed one first
        del boxes[MAX_FACES:]
    return boxes


class Bystanders:
    """The other faces of the last whole-frame pass, for frames answered by the crop track.

    In the service most frames follow the face in its crop (`full_every_s`), so
    their `FaceResult.faces` holds only the followed face; the whole-frame pass
    that sees everybody runs after publishing. Its other faces are kept here and
    shown on the tracked frames that follow, for at most `hold_s` (past that a
    bystander may have left): a viewer sees everybody, not just the one followed.
    """

    def __init__(self) -> None:
        self._faces: list[bf.Detection] = []
        self._stamp_ns = 0

    def update(self, searched: list[bf.Detection], result: FaceResult, stamp_ns: int) -> None:
        """Keep the faces of a whole-frame pass that are not the followed one."""
        followed = result.measured if result.measured is not None else result.target
        self._faces = [d for d in searched
                       if followed is None or _overlap(d.box, followed.box) < 0.3]
        self._stamp_ns = stamp_ns

    def current(self, result: FaceResult, stamp_ns: int, hold_s: float) -> list[bf.Detection]:
        """The kept faces if `result` is a tracked frame and they are recent enough."""
        if not result.tracked or not self._faces:
            return []
        if not 0 <= stamp_ns - self._stamp_ns <= hold_s * 1e9:
            return []
        return self._faces


def _overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """Intersection over union of two (x0, y0, x1, y1) boxes."""
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def to_message(result: FaceResult, stamp_ns: int, frame_id: str, width: int,
               height: int, others: list[bf.Detection] | None = None) -> m.FaceDetections:
    """Every face of one processed frame (`width` x `height` pixels), the followed one
    marked, with its fused distance before smoothing and its cues; no face: an empty
    list (so viewers clear their boxes). `others`: faces seen by a recent whole-frame
    pass (`Bystanders`), added unmarked."""
    estimate = result.estimate
    distance = None
    cues: list[m.DistanceCue] = []
    if estimate is not None and result.target is not None:
        distance = _metres(estimate.z_m)
        if estimate.fusion is not None:
            cues = [distance_cue(c) for c in estimate.fusion.cues[:MAX_CUES]]
    return m.FaceDetections(
        stamp_ns=max(stamp_ns, 0), frame_id=frame_id[:FRAME_ID_MAX],
        width=min(max(width, 1), SIDE_MAX), height=min(max(height, 1), SIDE_MAX),
        faces=_boxes(result, others or []), tracked=result.tracked,
        track=result.track if result.target is not None and result.track else None,
        distance_m=distance,
        cues=cues,
    )
