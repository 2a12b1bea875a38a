"""The [camera] and [face_detector] tables: defaults, typos and wrong types."""

from __future__ import annotations

import argparse

import pytest

from buddybot.camera import capture, detector
from buddybot.core.config import parse_config
from buddybot.core.errors import ConfigError
from buddybot.core.service import ServiceContext


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
    assert (fd.face_width_m, fd.fx, fd.fy, fd.model, fd.refine) == (0.15, 600.0, 600.0, "full",
                                                                     True)


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
    s = capture.effective_settings(ctx)
    assert (s.name, s.fps, s.encoding) == ("left", 25.0, "jpeg")
    ctx = ctx_for(detector, "[face_detector]\nfx = 500.0\nsmoothing = true\n",
                  "--fy", "510", "--no-smoothing", "--model", "short")
    d = detector.effective_settings(ctx)
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
        module.effective_settings(ctx_for(module, toml, *argv))  # type: ignore[attr-defined]


def test_max_pixels_and_full_every_s_reach_the_detector() -> None:
    d = detector.effective_settings(ctx_for(detector, ""))
    assert d.max_pixels == 3840 * 2160 and d.full_every_s == 0.25
    d = detector.effective_settings(ctx_for(
        detector, "[face_detector]\nmax_pixels = 2000000\nfull_every_s = 0.0\n"))
    assert (d.max_pixels, d.full_every_s) == (2_000_000, 0.0)
    d = detector.effective_settings(ctx_for(detector, "[face_detector]\nmax_pixels = 5\n",
                                            "--max-pixels", "307200"))
    assert d.max_pixels == 307200
