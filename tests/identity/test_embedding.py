"""Alignment maths (pure), the model loading with the project's OpenCV, bad input."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from buddybot.identity import embedding as e

ROOT = Path(__file__).resolve().parents[2]


def test_similarity_recovers_a_known_rotation_scale_and_shift() -> None:
    angle, scale, shift = np.deg2rad(17.0), 2.5, np.array([30.0, -12.0])
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    src = e.TEMPLATE.astype(np.float64)
    dst = (scale * src @ rot.T + shift).astype(np.float32)
    m = e.similarity(src.astype(np.float32), dst, e.WEIGHTS)
    np.testing.assert_allclose(m[:, :2], scale * rot, atol=1e-4)
    np.testing.assert_allclose(m[:, 2], shift, atol=1e-3)


def test_similarity_never_mirrors() -> None:
    mirrored = e.TEMPLATE.copy()
    mirrored[:, 0] = 150 - mirrored[:, 0]
    m = e.similarity(e.TEMPLATE, mirrored, e.WEIGHTS)
    assert np.linalg.det(m[:, :2]) > 0


def test_aligned_crop_puts_the_keypoints_on_the_template() -> None:
    """Dots drawn at keypoints of a tilted, scaled face land on TEMPLATE in the chip."""
    angle = np.deg2rad(-20.0)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    kps = (1.7 * (e.TEMPLATE - 75) @ rot.T + [320, 240]).astype(np.float32)
    for i, ((x, y), (tx, ty)) in enumerate(zip(kps, e.TEMPLATE, strict=True)):
        img = np.zeros((480, 640, 3), np.uint8)
        cv2.circle(img, (round(x), round(y)), 4, (0, 0, 255), -1)  # red in BGR
        chip = e.aligned_crop(img, kps)
        assert chip.shape == (e.CHIP, e.CHIP, 3) and chip.dtype == np.uint8
        red = chip[:, :, 0].astype(float)  # RGB: red first
        ys, xs = np.mgrid[:e.CHIP, :e.CHIP]
        cx, cy = (red * xs).sum() / red.sum(), (red * ys).sum() / red.sum()
        assert abs(cx - tx) < 1.0 and abs(cy - ty) < 1.0, i


@pytest.mark.parametrize("kps", [
    np.full((6, 2), np.nan), np.zeros((6, 2)), np.ones((3, 2)), np.ones(12), [[1, 2, 3]] * 6,
])
def test_bad_keypoints_are_refused(kps: object) -> None:
    with pytest.raises(e.BadKeypoints):
        e.aligned_crop(np.zeros((100, 100, 3), np.uint8), kps)  # type: ignore[arg-type]


def test_bad_images_and_vectors_are_refused() -> None:
    with pytest.raises(ValueError):
        e.aligned_crop(np.zeros((100, 100), np.uint8), e.TEMPLATE)
    for v in (np.zeros(128), np.full(128, np.nan)):
        with pytest.raises(ValueError):
            e.unit(v)
    assert np.linalg.norm(e.unit(np.arange(1, 129))) == pytest.approx(1.0)


def test_a_missing_model_file_says_how_to_install(tmp_path: Path) -> None:
    with pytest.raises(e.ModelNotFound, match="pip install"):
        e.locate(tmp_path / "nope.dat")
    bad = tmp_path / "bad.dat"
    bad.write_bytes(b"not a model")
    with pytest.raises(e.ModelNotFound, match="not a dlib face model"):
        e.Embedder.load(bad)


def test_the_project_opencv_is_the_one_pinned() -> None:
    """The alignment runs on the OpenCV pyproject.toml asks for (today 5.x)."""
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (spec,) = [d for d in deps if d.startswith("opencv-python-headless")]
    lowest = tuple(int(x) for x in re.findall(r"\d+", spec)[:2])
    assert tuple(int(x) for x in cv2.__version__.split(".")[:2]) >= lowest


def test_the_model_loads_and_embeds_a_unit_vector(embedder: e.Embedder) -> None:
    chip = np.random.default_rng(0).integers(0, 255, (e.CHIP, e.CHIP, 3), dtype=np.uint8)
    v = embedder.embed(chip)
    assert v.shape == (e.DIM,) and v.dtype == np.float32
    assert np.linalg.norm(v) == pytest.approx(1.0, abs=1e-5)
    with pytest.raises(ValueError):
        embedder.embed(chip[:100])
