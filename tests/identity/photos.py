"""Real photos of several people for the identity tests and benchmark, fetched, not committed.

* face_recognition 1.3.0's `tests/test_images` (MIT licence, in its source
  distribution on the package index): Obama (five photos, two of them
  cropped partial faces) and Biden (one); fetched with `pip download` into a
  cache folder once, so later runs need no network.
* scikit-image's `astronaut` (Eileen Collins, NASA, public domain) and the
  project's own crop of it (services/camera/data/astronaut_face.jpg): the
  same photo, so only a consistency check, never a "different photo" pair.
* Grace Hopper (tests/camera/data, public domain).
"""

from __future__ import annotations

import subprocess
import sys
import tarfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from buddybot.camera import blazeface as bf
from buddybot.camera import models
from buddybot.camera.facenet import FaceNet
from tests.cache import cache_root

ROOT = Path(__file__).resolve().parents[2]
SDIST = "face_recognition==1.3.0"
SHOTS = (  # file, person, source (the partial faces are crops of obama.jpg)
    ("obama.jpg", "obama", "obama"), ("obama2.jpg", "obama", "obama2"),
    ("obama3.jpg", "obama", "obama3"), ("obama_partial_face.jpg", "obama", "obama"),
    ("obama_partial_face2.jpg", "obama", "obama"), ("biden.jpg", "biden", "biden"))
FILES = tuple(f for f, _, _ in SHOTS)


class PhotosUnavailable(Exception):
    """The package index could not be reached to fetch the photos."""


@dataclass(frozen=True)
class Photo:
    name: str
    person: str
    bgr: np.ndarray
    source: str
    """Photos of one person from the same `source` are one shot, not independent."""


def cache_dir() -> Path:
    """$BUDDYBOT_CACHE, else ~/.cache/buddybot: outside the repository."""
    return cache_root() / "identity-photos"


def fetch(folder: Path | None = None) -> Path:
    """The folder holding FILES, downloading the sdist into it on first use."""
    folder = folder or cache_dir()
    if all((folder / f).is_file() for f in FILES):
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    run = subprocess.run(
        [sys.executable, "-m", "pip", "download", "--no-binary", ":all:", "--no-deps",
         "--disable-pip-version-check", "-q", "-d", str(folder), SDIST],
        capture_output=True, text=True, timeout=300)
    sdists = sorted(folder.glob("face_recognition-1.3.0.tar.gz"))
    if run.returncode != 0 or not sdists:
        raise PhotosUnavailable(f"pip download {SDIST} failed (package index unreachable?): "
                                f"{run.stderr.strip()[-300:]}")
    with tarfile.open(sdists[0]) as tar:
        for member in tar.getmembers():
            name = Path(member.name).name
            if name in FILES and member.isfile() and "/tests/test_images/" in member.name:
                extracted = tar.extractfile(member)
                assert extracted is not None
                (folder / name).write_bytes(extracted.read())
    missing = [f for f in FILES if not (folder / f).is_file()]
    if missing:
        raise PhotosUnavailable(f"{sdists[0].name} lacks {missing}")
    return folder


def _read(path: Path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert bgr is not None, path
    return bgr


def photos(folder: Path | None = None) -> list[Photo]:
    """Every test photo, one face each (raises PhotosUnavailable without the index)."""
    from skimage import data

    found = fetch(folder)
    out = [Photo(f.removesuffix(".jpg"), person, _read(found / f), source)
           for f, person, source in SHOTS]
    out.append(Photo("astronaut", "collins", cv2.cvtColor(data.astronaut(), cv2.COLOR_RGB2BGR),
                     "astronaut"))
    out.append(Photo("astronaut_face", "collins",
                     _read(ROOT / "services" / "camera" / "data" / "astronaut_face.jpg"),
                     "astronaut"))
    out.append(Photo("grace_hopper", "hopper", _read(ROOT / "tests" / "camera" / "data" /
                                                     "grace_hopper.jpg"), "grace_hopper"))
    return out


def detectors() -> tuple[FaceNet, FaceNet]:
    """The full-range detector and the short-range refiner, as face-detector runs them."""
    return (FaceNet(models.locate("full_sparse"), bf.FULL_SPARSE),
            FaceNet(models.locate("short"), bf.SHORT_RANGE))


def detection(nets: tuple[FaceNet, FaceNet], bgr: np.ndarray) -> bf.Detection:
    """The photo's one face (box and keypoints), refined as face-detector refines it."""
    full, short = nets
    found = full.detect(bgr)
    if len(found) != 1:
        raise AssertionError(f"expected one face, found {len(found)}")
    return short.refine(bgr, found[0]) or found[0]


def keypoints(nets: tuple[FaceNet, FaceNet], bgr: np.ndarray) -> np.ndarray:
    """The keypoints (6, 2) of the photo's one face."""
    return detection(nets, bgr).keypoints
