"""The [camera] and [face_detector] tables: defaults, typos and wrong types."""

from __future__ import annotations

import argparse
from pathlib import Path

import msgspec
import pytest

from buddybot.camera import capture, detector, models
from buddybot.camera.pipeline import FacePipeline, OwedSearch
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.runtime.config import parse_config
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.service import ServiceContext
from tests.camera import scenes


def ctx_for(module: object, toml: str, *argv: str) -> ServiceContext:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)  # type: ignore[attr-defined]
    args = parser.parse_args(list(argv))
    return ServiceContext(name="x", args=args, config=parse_config(toml, "test.toml"),
                          robot="buddy", connect=[])


def test_defaults() -> None:
    config = parse_config("")
    assert config.camera.name == "front" and config.camera.encoding == "bgr8"
    fd = config.face_detector
    assert (fd.face_width_m, fd.fx, fd.fy, fd.model, fd.refine) == (
        0.15, 600.0, 600.0, "full_sparse", True)


@pytest.mark.parametrize(("toml", "key"), [
    ("[camera]\nfps = 'fast'\n", "camera.fps"),
    ("[camera]\nresolution = 3\n", "resolution"),
    ("[face_detector]\nmodel = 'medium'\n", "face_detector.model"),
    ("[face_detector]\nfx = [1]\n", "face_detector.fx"),
])
def test_typos_and_wrong_types_name_the_key(toml: str, key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        parse_config(toml, "test.toml")


def test_command_line_overrides_config() -> None:
    ctx = ctx_for(capture, "[camera]\nname = 'left'\nfps = 10.0\nencoding = 'jpeg'\n",
                  "--fps", "25")
    s = capture.settings_from(ctx)
    assert (s.name, s.fps, s.encoding) == ("left", 25.0, "jpeg")
    ctx = ctx_for(detector, "[face_detector]\nfx = 500.0\nsmoothing = true\n",
                  "--fy", "510", "--no-smoothing", "--model", "short")
    d = detector.settings_from(ctx)
    assert (d.fx, d.fy, d.smoothing, d.model) == (500.0, 510.0, False, "short")


@pytest.mark.parametrize(("module", "toml", "argv", "text"), [
    (capture, "", ["--fps", "0"], "fps"),
    (capture, "[camera]\nname = 'a/b'\n", [], "camera name"),
    (capture, "", ["--width", "0"], "width"),
    (detector, "[face_detector]\nface_width_m = -1.0\n", [], "face_width_m"),
    (detector, "", ["--min-score", "1.5"], "min_score"),
    (detector, "[face_detector]\nbeta = -1.0\n", [], "beta"),
    (detector, "[face_detector]\nmax_pixels = 0\n", [], "max_pixels"),
    (detector, "", ["--max-pixels", str(16384 * 16384 + 1)], "max_pixels"),
    (detector, "[face_detector]\nfull_every_s = -1.0\n", [], "full_every_s"),
])
def test_impossible_values_are_config_errors(module: object, toml: str, argv: list[str],
                                             text: str) -> None:
    with pytest.raises(ConfigError, match=text):
        module.settings_from(ctx_for(module, toml, *argv))  # type: ignore[attr-defined]


def test_max_pixels_and_full_every_s_reach_the_detector() -> None:
    d = detector.settings_from(ctx_for(detector, ""))
    assert d.max_pixels == 3840 * 2160 and d.full_every_s == 0.25
    d = detector.settings_from(ctx_for(
        detector, "[face_detector]\nmax_pixels = 2000000\nfull_every_s = 0.0\n"))
    assert (d.max_pixels, d.full_every_s) == (2_000_000, 0.0)
    d = detector.settings_from(ctx_for(detector, "[face_detector]\nmax_pixels = 5\n",
                                            "--max-pixels", "307200"))
    assert d.max_pixels == 307200


# --- every [face_detector] key seen used, through the service's own wiring -----------

FRAME_NS = 33_333_333


def built(toml: str, *argv: str) -> tuple[FaceDetectorSettings, FacePipeline]:
    return detector.build(ctx_for(detector, "[face_detector]\n" + toml, *argv))


def test_model_choice_loads_that_file_and_its_layout() -> None:
    for toml, file, spec in [("", "face_detection_full_range_sparse.tflite", "full_sparse"),
                             ("model = 'full'", "face_detection_full_range.tflite", "full"),
                             ("model = 'short'", "face_detection_short_range.tflite", "short")]:
        _s, pipe = built(toml)
        assert (pipe.net.path.name, pipe.net.spec.name) == (file, spec)
        assert pipe.refiner is not None and pipe.refiner.spec.name == "short"


def test_model_path_is_loaded_with_the_chosen_model_layout(tmp_path: Path) -> None:
    copy = tmp_path / "mine.tflite"
    copy.write_bytes(models.locate("full").read_bytes())
    _s, pipe = built(f"model = 'full'\nmodel_path = '{copy}'")
    assert pipe.net.path == copy and pipe.net.spec.name == "full"


def test_min_score_decides_which_faces_count() -> None:
    img, _ = scenes.scene(scenes.astronaut(), 1.8)
    _s, default = built("")
    assert len(default.net.detect(img)) == 1
    score = default.net.detect(img)[0].score
    assert score < 0.97
    _s, strict = built("min_score = 0.97")
    assert strict.net.min_score == 0.97 and strict.net.detect(img) == []


def test_reconfigure_puts_live_settings_where_the_pipeline_reads_them() -> None:
    """A live change reaches the net's threshold, the tracker and the smoother; an
    unchanged filter keeps its state, and no min_score means the model's own again."""
    s, pipe = built("min_score = 0.97")
    smoother = pipe.smoother
    pipe.reconfigure(msgspec.structs.replace(s, switch_after_s=2.5, face_width_m=0.2))
    assert pipe.smoother is smoother and pipe.tracker.switch_after_s == 2.5
    assert pipe.s.face_width_m == 0.2 and pipe.net.min_score == 0.97
    pipe.reconfigure(msgspec.structs.replace(s, min_score=None, beta=5.0))
    assert pipe.net.min_score == pipe.net.spec.min_score
    assert pipe.smoother is not smoother and pipe.smoother.beta == 5.0


def test_refine_off_measures_with_the_whole_frame_box() -> None:
    img, _ = scenes.scene(scenes.grace_hopper(), 1.8)
    _s, on = built("")
    _s, off = built("refine = false")
    a, b = on.process(img, 1), off.process(img, 1)
    assert off.refiner is None and off.refined == 0 and b.measured is b.target
    assert on.refined == 1 and a.measured is not a.target


@pytest.mark.parametrize(("every", "searches"), [(0.0, 10), (0.1, 3), (0.25, 2), (1.0, 1)])
def test_full_every_s_sets_the_whole_frame_cadence(every: float, searches: int) -> None:
    """10 frames 33 ms apart: 0 searches every frame, 0.1 s frames 1, 5 and 9 (the
    first frame at least 0.1 s after the last pass), 0.25 s frames 1 and 9..."""
    _s, pipe = built(f"full_every_s = {every}")
    img, _ = scenes.scene(scenes.astronaut(), 1.2)
    for i in range(10):
        assert pipe.process(img, (i + 1) * FRAME_NS).point is not None
    assert pipe.searches == searches and pipe.tracked == 10 - searches


def test_smoothing_and_its_filter_constants() -> None:
    frames = [scenes.scene(scenes.astronaut(), 1.2, 200 + 20 * i, 240)[0] for i in range(6)]

    def lag(toml: str) -> float:
        _s, pipe = built(toml)
        result = None
        for i, img in enumerate(frames):
            result = pipe.process(img, (i + 1) * FRAME_NS)
        assert result is not None and result.point is not None and result.raw_point is not None
        return abs(result.point[1] - result.raw_point[1])

    assert lag("smoothing = false") == 0.0
    assert lag("") > 0.005
    # A higher cut-off follows faster: less lag behind the raw point.
    assert lag("min_cutoff_hz = 50.0\nbeta = 0.0") < lag("min_cutoff_hz = 0.5\nbeta = 0.0")
    # beta raises the cut-off with speed.
    assert lag("min_cutoff_hz = 0.5\nbeta = 50.0") < lag("min_cutoff_hz = 0.5\nbeta = 0.0")


def test_geometry_keys_reach_the_distance() -> None:
    img, _ = scenes.scene(scenes.grace_hopper(), 1.0)
    _s, base = built("smoothing = false")
    ref = base.process(img, 1)
    assert ref.estimate is not None and ref.estimate.from_eyes_m is not None
    _s, no_eyes = built("smoothing = false\neye_distance_m = 0.0")
    est = no_eyes.process(img, 1).estimate
    assert est is not None and est.from_eyes_m is None and est.z_m == est.from_width_m
    _s, wide = built("smoothing = false\nface_width_m = 0.30\neye_distance_m = 0.0")
    est2 = wide.process(img, 1).estimate
    assert est2 is not None and est2.z_m == pytest.approx(2 * est.z_m, rel=1e-6)
    _s, hfov = built("smoothing = false\nhfov_deg = 90.0")  # fx = 320 for 640 px
    far = hfov.process(img, 1)
    assert far.point is not None and ref.point is not None
    assert far.point[0] == pytest.approx(ref.point[0] * 320 / 600, rel=1e-6)
    _s, shifted = built("smoothing = false\ncx = 420.0\ncy = 140.0\nfx = 600.0\nfy = 300.0")
    p = shifted.process(img, 1).point
    assert p is not None and p[1] > ref.point[1] + 0.1 and p[2] < ref.point[2] - 0.1


def test_switch_after_s_and_threads_and_camera_reach_the_parts() -> None:
    s, pipe = built("switch_after_s = 2.5\nthreads = 2\ncamera = 'rear'")
    assert pipe.tracker.switch_after_s == 2.5
    assert pipe.net.model.num_threads == 2
    assert pipe.refiner is not None and pipe.refiner.model.num_threads == 2
    assert s.camera == "rear"  # type: ignore[attr-defined]


def test_debug_jpeg_quality_and_max_pixels_are_kept() -> None:
    s, _pipe = built("debug_jpeg_quality = 20\nmax_pixels = 1000")
    assert (s.debug_jpeg_quality, s.max_pixels) == (20, 1000)  # type: ignore[attr-defined]


def test_refine_input_px_sizes_the_crop_network() -> None:
    """The crop network runs at `refine_input_px` (its anchors and tensors with it); the
    short whole-frame model is shared only when it runs at that same size."""
    _s, pipe = built("refine_input_px = 80")
    assert pipe.refiner is not None and pipe.refiner.spec.input_size == 80
    assert pipe.refiner.model.input.shape == (1, 80, 80, 3)
    assert pipe.refiner.spec.anchor_count == 10 * 10 * 2 + 5 * 5 * 6
    img, _ = scenes.scene(scenes.astronaut(), 1.0)
    assert pipe.process(img, FRAME_NS).point is not None and pipe.refined == 1
    _s, same = built("model = 'short'\nrefine_input_px = 128")
    assert same.refiner is same.net
    _s, other = built("model = 'short'")
    assert other.refiner is not other.net and other.net.spec.input_size == 128


def test_defer_after_ms_is_waited_before_the_owed_work_and_only_then() -> None:
    """`defer_after_ms` reaches `after_publishing`: with a whole-frame pass owed, the wait
    comes first and then the pass runs; with nothing owed there is no wait at all."""
    s, pipe = built("defer_after_ms = 7.5\nfull_every_s = 0.5\niris = false")
    img, _ = scenes.scene(scenes.astronaut(), 1.0)
    waits: list[float] = []
    first = pipe.process(img, FRAME_NS, defer=True)  # first frame: searched inline
    assert first.owed == ()
    assert detector.after_publishing(pipe, first.owed, s.defer_after_ms / 1000,  # type: ignore[attr-defined]
                                     waits.append) is None
    assert waits == []
    t = 20 * FRAME_NS  # past full_every_s: a pass is due, answered from the crop
    r = pipe.process(img, t, defer=True)
    assert r.tracked and [type(w) for w in r.owed] == [OwedSearch]
    searches = pipe.searches
    faces = detector.after_publishing(pipe, r.owed, s.defer_after_ms / 1000,  # type: ignore[attr-defined]
                                      waits.append)
    assert waits == [0.0075] and pipe.searches == searches + 1 and faces
