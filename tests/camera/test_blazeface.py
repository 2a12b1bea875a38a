"""Pure BlazeFace maths: anchors, letterbox, decoding, weighted NMS (no network)."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.camera import blazeface as bf


def test_anchor_counts_match_the_models() -> None:
    assert bf.anchors(bf.FULL_RANGE).shape == (2304, 2)
    assert bf.anchors(bf.SHORT_RANGE).shape == (896, 2)


def test_full_range_anchors_are_a_48_grid_in_row_major_order() -> None:
    a = bf.anchors(bf.FULL_RANGE)
    assert a[0] == pytest.approx((0.5 / 48, 0.5 / 48))
    assert a[1] == pytest.approx((1.5 / 48, 0.5 / 48))
    assert a[48] == pytest.approx((0.5 / 48, 1.5 / 48))


def test_short_range_anchors_two_per_cell_then_six_per_cell() -> None:
    a = bf.anchors(bf.SHORT_RANGE)
    assert a[0] == pytest.approx(a[1])  # two anchors share the first 16x16 cell
    assert a[0] == pytest.approx((0.5 / 16, 0.5 / 16))
    assert a[512] == pytest.approx((0.5 / 8, 0.5 / 8))
    assert np.allclose(a[512:518], a[512])  # six anchors per 8x8 cell
    assert a[518] == pytest.approx((1.5 / 8, 0.5 / 8))


def test_letterbox_round_trip_for_a_landscape_image() -> None:
    lb = bf.Letterbox.fit(640, 480, 192)
    assert lb.resized_shape(640, 480) == (192, 144)
    assert (lb.pad_x, lb.pad_y) == (0, 24)
    # The image's corners map from the normalised input's padded area.
    pts = np.array([[0.0, 24 / 192], [1.0, 168 / 192]], np.float32)
    assert lb.to_image(pts) == pytest.approx(np.array([[0, 0], [640, 480]], np.float32))


def _raw(spec: bf.ModelSpec, index: int, logit: float, values: list[float]) -> tuple:
    n = len(bf.anchors(spec))
    scores = np.full((1, n, 1), -50.0, np.float32)
    boxes = np.zeros((1, n, 16), np.float32)
    scores[0, index, 0] = logit
    boxes[0, index, :] = values
    return scores, boxes


def test_decode_places_box_and_keypoints_relative_to_the_anchor() -> None:
    spec = bf.FULL_RANGE
    anchor = bf.anchors(spec)
    idx = 48 * 20 + 10
    values = [9.6, -4.8, 38.4, 48.0] + [0.0, 0.0] * 5 + [19.2, 19.2]
    scores, boxes = _raw(spec, idx, 2.0, values)
    s, b, k = bf.decode(scores, boxes, anchor, spec)
    assert s == pytest.approx([1 / (1 + np.exp(-2.0))])
    cx, cy = anchor[idx] + np.array([9.6, -4.8]) / 192
    w, h = 38.4 / 192, 48.0 / 192
    assert b[0] == pytest.approx([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2], abs=1e-6)
    assert k[0, 0] == pytest.approx(anchor[idx])
    assert k[0, 5] == pytest.approx(anchor[idx] + 0.1)


def test_decode_applies_the_threshold_to_the_logit() -> None:
    spec = bf.FULL_RANGE
    scores, boxes = _raw(spec, 5, 0.3, [0.0] * 16)  # sigmoid(0.3) = 0.574 < 0.6
    assert bf.decode(scores, boxes, bf.anchors(spec), spec)[0].size == 0
    assert bf.decode(scores, boxes, bf.anchors(spec), spec, min_score=0.5)[0].size == 1


def test_huge_logits_are_clipped_not_overflowing() -> None:
    spec = bf.FULL_RANGE
    scores, boxes = _raw(spec, 5, 1e30, [0.0] * 16)
    s, _, _ = bf.decode(scores, boxes, bf.anchors(spec), spec)
    assert s == pytest.approx([1.0])


def test_weighted_nms_averages_a_cluster_by_score_and_keeps_separate_faces() -> None:
    boxes = np.array([[0.0, 0.0, 1.0, 1.0], [0.1, 0.0, 1.1, 1.0], [5.0, 5.0, 6.0, 6.0]],
                     np.float32)
    scores = np.array([0.9, 0.6, 0.8], np.float32)
    kps = np.zeros((3, 6, 2), np.float32)
    kps[1] += 1.0
    out = bf.weighted_nms(scores, boxes, kps, 0.3)
    assert [round(s, 2) for s, _, _ in out] == [0.9, 0.8]
    merged_box = out[0][1]
    assert merged_box[0] == pytest.approx(0.1 * 0.6 / 1.5)  # score-weighted mean
    assert out[0][2][0, 0] == pytest.approx(0.6 / 1.5)
    assert out[1][1] == pytest.approx(boxes[2])


def test_weighted_nms_of_nothing_is_nothing() -> None:
    empty = np.zeros((0,), np.float32)
    assert bf.weighted_nms(empty, np.zeros((0, 4), np.float32),
                           np.zeros((0, 6, 2), np.float32), 0.3) == []


def test_iou_of_disjoint_and_identical_boxes() -> None:
    box = np.array([0, 0, 2, 2], np.float32)
    others = np.array([[0, 0, 2, 2], [3, 3, 4, 4], [1, 0, 3, 2]], np.float32)
    assert bf.iou(box, others) == pytest.approx([1.0, 0.0, 1 / 3])


def test_postprocess_returns_image_pixels() -> None:
    spec = bf.FULL_RANGE
    anchor = bf.anchors(spec)
    idx = 48 * 24 + 24  # the cell just right of and below the input centre
    scores, boxes = _raw(spec, idx, 3.0, [0.0, 0.0, 19.2, 19.2] + [0.0] * 12)
    lb = bf.Letterbox.fit(640, 480, 192)
    faces = bf.postprocess(scores, boxes, anchor, spec, lb)
    assert len(faces) == 1
    cx, cy = faces[0].centre
    assert cx == pytest.approx(anchor[idx][0] * 192 / 0.3, abs=1e-3)
    assert cy == pytest.approx((anchor[idx][1] * 192 - 24) / 0.3, abs=1e-3)
    assert faces[0].width == pytest.approx(19.2 / 0.3, rel=1e-5)


@pytest.mark.parametrize("seed", range(8))
def test_small_and_array_nms_give_the_same_faces(seed: int) -> None:
    """The Python-float NMS (few candidates) and the array one (many) are one rule:
    on random overlapping candidates, the same clusters, scores and means."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    centres = rng.uniform(0, 3, (n, 2)).astype(np.float32)
    sizes = rng.uniform(0.3, 1.5, (n, 1)).astype(np.float32)
    boxes = np.concatenate([centres - sizes / 2, centres + sizes / 2], axis=1)
    scores = rng.uniform(0.5, 1.0, n).astype(np.float32)
    rows = np.concatenate([boxes, rng.normal(size=(n, 12)).astype(np.float32)], axis=1)
    small = bf._clusters_small(scores, boxes.tolist(), rows, 0.3, 16)
    array = bf._clusters(scores, boxes, rows, 0.3, 16)
    assert len(small) == len(array) > 0
    for (s1, m1), (s2, m2) in zip(small, array, strict=True):
        assert s1 == pytest.approx(s2)
        assert m1 == pytest.approx(m2, abs=1e-5)


def test_many_candidates_take_the_array_path_with_the_same_result() -> None:
    """Above SMALL_NMS candidates `weighted_nms` switches path; a cluster of
    identical boxes gives the same single face either way."""
    n = bf.SMALL_NMS + 5
    boxes = np.tile(np.array([[0.0, 0.0, 1.0, 1.0]], np.float32), (n, 1))
    scores = np.linspace(0.9, 0.6, n).astype(np.float32)
    kps = np.zeros((n, 6, 2), np.float32)
    many = bf.weighted_nms(scores, boxes, kps, 0.3)
    few = bf.weighted_nms(scores[:3], boxes[:3], kps[:3], 0.3)
    assert len(many) == len(few) == 1
    assert many[0][0] == pytest.approx(0.9) and many[0][1] == pytest.approx(boxes[0])


def test_a_moved_letterbox_maps_a_crop_into_the_frame() -> None:
    """A crop at (100, 40) of a frame: decoding through `moved` gives frame pixels,
    the crop's own pixels plus the offset."""
    lb = bf.Letterbox.fit(300, 300, 128)
    pts = np.array([[0.25, 0.5], [1.0, 0.0]], np.float32)
    assert lb.moved(100, 40).to_image(pts) == pytest.approx(lb.to_image(pts) + np.array([100, 40]))
    spec = bf.SHORT_RANGE
    scores, boxes = _raw(spec, 40, 3.0, [0.0, 0.0, 12.8, 12.8] + [0.0] * 12)
    anchor = bf.anchors(spec)
    in_crop = bf.postprocess(scores, boxes, anchor, spec, lb)[0]
    in_frame = bf.postprocess(scores, boxes, anchor, spec, lb.moved(100, 40))[0]
    assert in_frame.box == pytest.approx(np.add(in_crop.box, [100, 40, 100, 40]))
    assert in_frame.keypoints == pytest.approx(in_crop.keypoints + np.array([100, 40]))
