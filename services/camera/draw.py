"""Debug drawing: box, score, keypoints and distance on a copy of the frame."""

from __future__ import annotations

import cv2
import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera.geometry import DistanceEstimate

_TARGET = (0, 220, 0)
_OTHER = (0, 160, 255)
_KEYPOINT_COLOURS = ((255, 0, 0), (0, 0, 255), (0, 255, 255), (255, 0, 255), (255, 255, 0),
                     (0, 255, 0))


def render(bgr: np.ndarray, faces: list[bf.Detection], target: bf.Detection | None,
           estimate: DistanceEstimate | None,
           measured: bf.Detection | None = None) -> np.ndarray:
    """Every face outlined (the followed one green with its distance), keypoints dotted;
    the followed face is drawn as measured (refined) when that is given."""
    out = bgr.copy()
    shown = [measured if (det is target and measured is not None) else det for det in faces]
    target = measured if measured is not None else target
    for det in shown:
        chosen = det is target
        colour = _TARGET if chosen else _OTHER
        x0, y0, x1, y1 = (round(v) for v in det.box)
        cv2.rectangle(out, (x0, y0), (x1, y1), colour, 2)
        label = f"{det.score:.2f}"
        if chosen and estimate is not None:
            label += f"  {estimate.z_m:.2f} m"
        cv2.putText(out, label, (x0, max(y0 - 6, 12)), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1,
                    cv2.LINE_AA)
        for (u, v), c in zip(det.keypoints, _KEYPOINT_COLOURS, strict=True):
            cv2.circle(out, (round(float(u)), round(float(v))), 3, c, -1)
    if not faces:
        cv2.putText(out, "no face", (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 255), 1,
                    cv2.LINE_AA)
    elif estimate is not None and estimate.fusion is not None:
        # Which distance cues were used, with their weights (`0.52 m iris_held 47% ...`).
        # On a dark strip, so it reads on any background.
        text = estimate.fusion.summary()
        (tw, th), _base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        h = out.shape[0]
        cv2.rectangle(out, (4, h - 16 - th), (16 + tw, h - 4), (0, 0, 0), -1)
        cv2.putText(out, text, (10, h - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5, _TARGET, 1,
                    cv2.LINE_AA)
    return out
