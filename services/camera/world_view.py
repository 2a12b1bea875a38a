"""The simulated world as the camera films it: real face photos where the people are.

Each person in front of the camera is drawn far to near (so a nearer
person hides a farther one) as shoulders and a head: the face photo,
scaled so that the box BlazeFace finds on it is `face_width_m` wide at the
person's depth, through the same pinhole the detector measures with. A
face turned more than `views.MAX_TURN_RAD` away shows the back of a head;
a covered camera films darkness. Pure given the snapshot: `frame(snapshot)`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from buddybot.camera.sim import background, compose, oval_mask
from buddybot.sim import faces, views
from buddybot.sim.world import Snapshot

CLOTHES = ((70, 60, 50), (40, 40, 90), (90, 70, 40), (50, 80, 60), (80, 50, 80))
"""BGR colours of the shoulders, by person id."""
HAIR = (40, 50, 60)


class WorldCamera:
    """Frames of a world for one lens; the face photos are read once."""

    def __init__(self, lens: views.Lens) -> None:
        self.lens = lens
        self._background = background(lens.width, lens.height)
        self._dark = np.full((lens.height, lens.width, 3), 6, np.uint8)
        self._sprites: dict[str, tuple[np.ndarray, np.ndarray, float]] = {}

    def _sprite(self, name: str) -> tuple[np.ndarray, np.ndarray, float]:
        found = self._sprites.get(name)
        if found is None:
            image = cv2.imread(str(faces.path(name)), cv2.IMREAD_COLOR)
            if image is None:
                raise FileNotFoundError(f"simulated camera: cannot read {faces.path(name)}")
            found = (image, oval_mask(image), faces.catalogue()[name].box_frac)
            self._sprites[name] = found
        return found

    def frame(self, snapshot: Snapshot) -> np.ndarray:
        if snapshot.camera_covered:
            return self._dark.copy()
        out = self._background.copy()
        for face in views.camera_view(snapshot, self.lens):
            self._draw(out, face)
        return out

    def _draw(self, out: np.ndarray, face: views.FaceView) -> None:
        b = face.box_px
        u, v = round(face.u), round(face.v)
        colour = CLOTHES[(face.person.id - 1) % len(CLOTHES)]
        top = round(face.v + views.BODY_TOP * b)
        half = round(views.BODY_HALF_W * b)
        shoulders = top + round(0.9 * b)
        cv2.ellipse(out, (u, shoulders), (half, round(0.9 * b)), 0, 180, 360, colour, -1,
                    cv2.LINE_AA)
        cv2.rectangle(out, (u - half, shoulders), (u + half, self.lens.height), colour, -1)
        if face.person.turned > views.MAX_TURN_RAD:
            cv2.ellipse(out, (u, v), (round(views.HEAD_HALF_W * b),
                        round(views.HEAD_HALF_H * b)), 0, 0, 360, HAIR, -1, cv2.LINE_AA)
            return
        sprite, mask, box_frac = self._sprite(face.person.face)
        side = b / box_frac
        squash = max(math.cos(face.person.turned), 0.3)
        width = max(1, round(sprite.shape[1] * squash))
        if width != sprite.shape[1]:
            sprite = cv2.resize(sprite, (width, sprite.shape[0]))
            mask = cv2.resize(mask, (width, mask.shape[0]))
        pasted = compose(out, sprite, mask, face.u, face.v, side)
        out[:] = pasted
