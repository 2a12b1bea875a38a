"""The real face networks, each loaded at most once per test process."""

from __future__ import annotations

import functools

import cv2

from buddybot.camera import blazeface as bf
from buddybot.camera import models
from buddybot.camera.facenet import FaceNet
from buddybot.camera.iris import IrisNet


class Networks:
    """Each network built at most once per (model, threshold); stateless between frames."""

    def __init__(self) -> None:
        cv2.setNumThreads(1)

    @functools.cache  # noqa: B019 (one instance per process, kept for the session)
    def face(self, name: str, min_score: float | None = None) -> FaceNet:
        return FaceNet(models.locate(name), bf.SPECS[name], min_score)

    @functools.cache  # noqa: B019
    def iris(self) -> IrisNet:
        return IrisNet()
