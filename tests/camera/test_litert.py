"""The LiteRT wrapper: real models loaded, layouts checked, bad files refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from buddybot.camera import models
from buddybot.camera.litert import ANY, LiteModel, ModelLoadError, Tensor
from buddybot.runtime.errors import ConfigError

BLAZE_FULL_IN = Tensor((1, 192, 192, 3))
BLAZE_FULL_OUT = [Tensor((1, 2304, 1)), Tensor((1, 2304, 16))]


def data_file(name: str) -> Path:
    folder = models.package_data_dir()
    assert folder is not None
    return folder / name


def test_outputs_come_back_in_the_order_asked_for_whatever_the_model_order() -> None:
    model = LiteModel(models.locate("full_sparse"), BLAZE_FULL_IN, BLAZE_FULL_OUT)
    scores, boxes = model.run(np.zeros((1, 192, 192, 3), np.float32))
    assert scores.shape == (1, 2304, 1) and boxes.shape == (1, 2304, 16)
    boxes2, scores2 = LiteModel(models.locate("full_sparse"), BLAZE_FULL_IN,
                                BLAZE_FULL_OUT[::-1]).run(np.zeros((1, 192, 192, 3), np.float32))
    assert np.array_equal(scores, scores2) and np.array_equal(boxes, boxes2)


def test_outputs_by_name_and_free_dimensions() -> None:
    """The landmark models have outputs told apart by name (the iris module's use)."""
    model = LiteModel(data_file("iris_landmark.tflite"), Tensor((1, ANY, ANY, 3)),
                      [Tensor((1, 15), name="output_iris"), Tensor((1, 213))])
    iris, contours = model.run(np.zeros((1, 64, 64, 3), np.float32))
    assert iris.shape == (1, 15) and contours.shape == (1, 213)
    assert model.input_shape == (1, ANY, ANY, 3)


def test_outputs_are_copies_not_views_of_the_interpreter() -> None:
    model = LiteModel(models.locate("short"), Tensor((1, 128, 128, 3)),
                      [Tensor((1, 896, 1)), Tensor((1, 896, 16))])
    first = model.run(np.zeros((1, 128, 128, 3), np.float32))[0].copy()
    kept = model.run(np.zeros((1, 128, 128, 3), np.float32))[0]
    model.run(np.ones((1, 128, 128, 3), np.float32))
    assert np.array_equal(kept, first)


def test_a_model_error_is_a_config_error() -> None:
    assert issubclass(ModelLoadError, ConfigError)  # so the service exits 2


@pytest.mark.parametrize(("content", "text"), [
    (b"", "cannot load model"),
    (b"not a flatbuffer at all" * 10, "cannot load model"),
], ids=["empty", "garbage"])
def test_files_litert_cannot_load_are_refused_naming_the_file(tmp_path: Path, content: bytes,
                                                              text: str) -> None:
    path = tmp_path / "bad.tflite"
    path.write_bytes(content)
    with pytest.raises(ModelLoadError, match=text) as info:
        LiteModel(path, BLAZE_FULL_IN, BLAZE_FULL_OUT)
    assert str(path) in str(info.value) and "1x192x192x3" in str(info.value)


def test_a_truncated_model_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "half.tflite"
    path.write_bytes(models.locate("full_sparse").read_bytes()[:50_000])
    with pytest.raises(ModelLoadError, match=r"half\.tflite"):
        LiteModel(path, BLAZE_FULL_IN, BLAZE_FULL_OUT)


def test_a_missing_file_is_refused_naming_it(tmp_path: Path) -> None:
    with pytest.raises(ModelLoadError, match=r"nowhere\.tflite"):
        LiteModel(tmp_path / "nowhere.tflite", BLAZE_FULL_IN, BLAZE_FULL_OUT)


@pytest.mark.parametrize(("name", "wrong"), [
    ("face_detection_short_range.tflite", "input"),
    ("iris_landmark.tflite", "input"),
    ("face_landmark.tflite", "output"),
])
def test_a_real_model_of_another_layout_says_what_was_expected(name: str, wrong: str) -> None:
    with pytest.raises(ModelLoadError, match=f"wrong tensor layout \\({wrong}") as info:
        LiteModel(data_file(name), BLAZE_FULL_IN, BLAZE_FULL_OUT)
    text = str(info.value)
    assert name in text and "expected input 1x192x192x3 float32" in text
    assert "1x2304x16" in text and "the file has input" in text


def test_an_ambiguous_output_match_is_refused() -> None:
    """Two expected outputs that the same tensor would satisfy cannot be told apart."""
    with pytest.raises(ModelLoadError, match="output"):
        LiteModel(models.locate("full_sparse"), BLAZE_FULL_IN,
                  [Tensor((1, 2304, ANY)), Tensor((1, 2304, 1))])


def test_a_resize_the_outputs_do_not_follow_is_refused_naming_the_file() -> None:
    model = LiteModel(models.locate("short"), Tensor((1, 128, 128, 3)),
                      [Tensor((1, 896, 1)), Tensor((1, 896, 16))])
    with pytest.raises(ModelLoadError, match=r"face_detection_short_range\.tflite"):
        # 96 px gives 504 anchors, not 896: the expected outputs cannot match.
        model.resize_input(Tensor((1, 96, 96, 3)), [Tensor((1, 896, 1)), Tensor((1, 896, 16))])
    model.resize_input(Tensor((1, 96, 96, 3)), [Tensor((1, 504, 1)), Tensor((1, 504, 16))])
    scores, boxes = model.run(np.zeros((1, 96, 96, 3), np.float32))
    assert scores.shape == (1, 504, 1) and boxes.shape == (1, 504, 16)
