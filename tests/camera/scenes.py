"""Real face photos composed at known distances and positions (test data).

Ground truth comes from the photos, not from the detector: the pupils of
each photo were located by hand (zoomed crops), and a person with the
adult mean inter-pupillary distance (63 mm) at distance Z in front of a
camera with focal length fx shows `fx * 0.063 / Z` pixels between the
pupils. Scaling the photo to that and pasting it with the eyes' midpoint
at a chosen pixel gives a frame whose true 3-D face position is known.

* astronaut (scikit-image, NASA, public domain): used for tuning;
* grace_hopper (US Navy photo, public domain; the copy matplotlib ships as
  sample data, saved in data/ so the tests need no matplotlib): held out,
  never used to choose a parameter.

Hard scenes (small and partial faces) put the same photos where
detectors fail: 20-60 px faces (3.0-4.2 m and 1.5-2.7 m at fx 600), faces 25%
and 50% outside each edge, two faces, dark, motion- and defocus-blurred
and JPEG quality 20 frames, over backdrops from scikit-image's non-face
pictures. Each scene carries its true face boxes, computed from a face box
marked by hand on each photo (cheek to cheek, hairline to chin), so recall
is measured against the photos, never against a detector. Everything is a
pure function of fixed seeds.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import cv2
import numpy as np
from skimage import data

from buddybot.camera import blazeface as bf
from buddybot.camera import models
from buddybot.camera.detector import load_refiner
from buddybot.camera.facenet import FaceNet
from buddybot.camera.pipeline import FacePipeline, FaceResult
from buddybot.camera.settings import FaceDetectorSettings
from buddybot.camera.sim import compose
from buddybot.identity.tracks import iou

IPD_M = 0.063
WIDTH, HEIGHT = 640, 480
FX = 600.0

Box = tuple[float, float, float, float]
"""(x0, y0, x1, y1) in pixels."""


@dataclass(frozen=True)
class Photo:
    name: str
    bgr: np.ndarray
    right_pupil: tuple[float, float]  # subject's right eye (image left)
    left_pupil: tuple[float, float]
    face: Box | None = None
    """The face marked by hand (cheek to cheek, hairline to chin), photo pixels."""

    @property
    def ipd_px(self) -> float:
        return float(np.hypot(self.left_pupil[0] - self.right_pupil[0],
                              self.left_pupil[1] - self.right_pupil[1]))

    @property
    def eyes_mid(self) -> tuple[float, float]:
        return ((self.right_pupil[0] + self.left_pupil[0]) / 2,
                (self.right_pupil[1] + self.left_pupil[1]) / 2)


def astronaut() -> Photo:
    bgr = cv2.cvtColor(data.astronaut(), cv2.COLOR_RGB2BGR)
    return Photo("astronaut", bgr, (203.1, 101.3), (246.3, 103.1), (177.0, 76.0, 272.0, 178.0))


def grace_hopper() -> Photo:
    path = Path(__file__).parent / "data" / "grace_hopper.jpg"
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert bgr is not None, path
    return Photo("grace_hopper", bgr, (223.3, 188.3), (304.2, 185.8),
                 (165.0, 150.0, 357.0, 345.0))


def background(width: int = WIDTH, height: int = HEIGHT, seed: int = 0) -> np.ndarray:
    """A textured non-face backdrop (noise + stripes), deterministic."""
    rng = np.random.default_rng(seed)
    noise = rng.integers(60, 120, (height, width, 3), dtype=np.uint8)
    img: np.ndarray = cv2.GaussianBlur(noise, (0, 0), 3)
    for x in range(0, width, 80):
        cv2.rectangle(img, (x, 0), (x + 30, height), (150, 140, 120), -1)
    return img


@dataclass(frozen=True)
class Placed:
    """A face put into a frame: where its eyes' midpoint is and how far it is."""

    u: float
    v: float
    z_m: float
    scale: float


def place(frame: np.ndarray, photo: Photo, z_m: float, u: float, v: float,
          fx: float = 600.0) -> tuple[np.ndarray, Placed]:
    """Paste `photo` as if the person stood `z_m` away with the eyes' midpoint at (u, v)."""
    scale = fx * IPD_M / z_m / photo.ipd_px
    h, w = photo.bgr.shape[:2]
    mx, my = photo.eyes_mid
    cx = u + (w / 2 - mx) * scale
    cy = v + (h / 2 - my) * scale
    mask = _feather(h, w, photo.right_pupil, photo.left_pupil)
    return compose(frame, photo.bgr, mask, cx, cy, h * scale), Placed(u, v, z_m, scale)


@cache
def _feather(h: int, w: int, right_pupil: tuple[float, float],
             left_pupil: tuple[float, float]) -> np.ndarray:
    """Feathered ellipse around the face so the photo's straight edges do not stand out
    (depends on the eyes only; cached because blurring it costs more than the paste)."""
    ipd = float(np.hypot(left_pupil[0] - right_pupil[0], left_pupil[1] - right_pupil[1]))
    mx, my = (right_pupil[0] + left_pupil[0]) / 2, (right_pupil[1] + left_pupil[1]) / 2
    hard = np.zeros((h, w), np.float32)
    cv2.ellipse(hard, (int(mx), int(my + 0.4 * ipd)), (int(ipd * 2.2), int(ipd * 2.8)),
                0, 0, 360, 1.0, -1)
    mask: np.ndarray = cv2.GaussianBlur(hard, (0, 0), ipd * 0.2)
    mask.setflags(write=False)
    return mask


def scene(photo: Photo, z_m: float, u: float = WIDTH / 2, v: float = HEIGHT / 2,
          fx: float = 600.0, seed: int = 0) -> tuple[np.ndarray, Placed]:
    return place(background(seed=seed), photo, z_m, u, v, fx)


def truth(p: Placed, fx: float = 600.0, fy: float = 600.0, cx: float = WIDTH / 2,
          cy: float = HEIGHT / 2) -> tuple[float, float, float]:
    """True ROS point (x fwd, y left, z up) of the eyes' midpoint."""
    return p.z_m, -(p.u - cx) * p.z_m / fx, -(p.v - cy) * p.z_m / fy


# --- Hard scenes: small and partial faces -----------------------------------------------


def scale_at(photo: Photo, z_m: float, fx: float = FX) -> float:
    """Photo pixels -> frame pixels for a person `z_m` away (63 mm between the pupils)."""
    return fx * IPD_M / z_m / photo.ipd_px


def face_box(photo: Photo, p: Placed) -> Box:
    """Where the photo's hand-marked face box lands in the frame (may leave the frame)."""
    assert photo.face is not None, f"{photo.name}: no face box marked"
    mx, my = photo.eyes_mid
    x0, y0, x1, y1 = photo.face
    return (p.u + (x0 - mx) * p.scale, p.v + (y0 - my) * p.scale,
            p.u + (x1 - mx) * p.scale, p.v + (y1 - my) * p.scale)


def place_face(frame: np.ndarray, photo: Photo, z_m: float, bx: float, by: float,
               fx: float = FX) -> tuple[np.ndarray, Box]:
    """Paste `photo` at `z_m` with the centre of its face box at (bx, by); the true box."""
    assert photo.face is not None
    scale = scale_at(photo, z_m, fx)
    mx, my = photo.eyes_mid
    fcx, fcy = (photo.face[0] + photo.face[2]) / 2, (photo.face[1] + photo.face[3]) / 2
    img, p = place(frame, photo, z_m, bx - (fcx - mx) * scale, by - (fcy - my) * scale, fx)
    return img, face_box(photo, p)


def _cover(img: np.ndarray, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """`img` scaled to cover width x height and centre-cropped; grey becomes BGR."""
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    s = max(width / img.shape[1], height / img.shape[0])
    big = cv2.resize(img, (max(width, round(img.shape[1] * s)),
                           max(height, round(img.shape[0] * s))), interpolation=cv2.INTER_LINEAR)
    y0, x0 = (big.shape[0] - height) // 2, (big.shape[1] - width) // 2
    return np.ascontiguousarray(big[y0:y0 + height, x0:x0 + width])


@cache
def _backdrops() -> tuple[np.ndarray, ...]:
    """Non-face scenes of varied texture and brightness: the synthetic one, then
    scikit-image pictures with no people in them (brick wall, gravel, grass, a
    coffee cup, a rocket; the grey ones tinted so skin colour is not the only
    colour in the frame)."""
    def tint(grey: np.ndarray, bgr: tuple[float, float, float]) -> np.ndarray:
        return (cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR) * np.array(bgr, np.float32)).astype(
            np.uint8)

    pictures = [
        background(seed=0),
        _cover(tint(data.brick(), (0.75, 0.85, 1.0))),
        _cover(tint(data.gravel(), (0.9, 0.95, 1.0))),
        _cover(tint(data.grass(), (0.6, 1.0, 0.7))),
        _cover(cv2.cvtColor(data.coffee(), cv2.COLOR_RGB2BGR)),
        _cover(cv2.cvtColor(data.rocket(), cv2.COLOR_RGB2BGR)),
    ]
    for p in pictures:
        p.setflags(write=False)
    return tuple(pictures)


def backdrop(i: int) -> np.ndarray:
    """The i-th backdrop (cycling), 640x480 BGR, read-only (compose copies it)."""
    pictures = _backdrops()
    return pictures[i % len(pictures)]


@dataclass(frozen=True)
class HardScene:
    """One frame and the true boxes of every face in it."""

    family: str
    name: str
    bgr: np.ndarray
    boxes: tuple[Box, ...]


@dataclass(frozen=True)
class Sequence:
    """`length` consecutive frames at 30 fps, rendered on demand (a list of them would hold
    ~140 MB); iterating yields (frame, true box) pairs."""

    name: str
    length: int
    render: Callable[[int], tuple[np.ndarray, Box]]

    def __iter__(self) -> Iterator[tuple[np.ndarray, Box]]:
        return (self.render(i) for i in range(self.length))


PHOTOS: tuple[Callable[[], Photo], ...] = (astronaut, grace_hopper)
GRID = [(u, v) for v in (120, 240, 360) for u in (110, 320, 530)]
"""Face centres spread over the frame (3x3)."""


def _jitter(rng: np.random.Generator, u: float, v: float, px: float = 25.0) -> tuple[float, float]:
    return u + float(rng.uniform(-px, px)), v + float(rng.uniform(-px, px))


def _sized(family: str, distances: tuple[float, ...], seed: int) -> list[HardScene]:
    """Each photo at each distance at nine jittered places, on cycling backdrops."""
    rng = np.random.default_rng(seed)
    out = []
    k = 0
    for photo_fn in PHOTOS:
        photo = photo_fn()
        for z in distances:
            for u, v in GRID:
                bx, by = _jitter(rng, u, v)
                img, box = place_face(backdrop(k), photo, z, bx, by)
                out.append(HardScene(family, f"{photo.name} {z:.1f}m ({bx:.0f},{by:.0f}) bg{k % 6}",
                                     img, (box,)))
                k += 1
    return out


def far() -> list[HardScene]:
    """Faces 20-30 px wide: 3.0-4.2 m at fx 600 (the issue's 3-4 m), 72 scenes."""
    return _sized("far", (3.0, 3.4, 3.8, 4.2), seed=11)


def small() -> list[HardScene]:
    """Faces 31-58 px wide: 1.5-2.7 m, 72 scenes."""
    return _sized("small", (1.5, 1.9, 2.3, 2.7), seed=12)


def _edge(fraction: float, seed: int) -> list[HardScene]:
    """Faces `fraction` of their box outside each of the four edges, 48 scenes."""
    rng = np.random.default_rng(seed)
    out = []
    k = 0
    for photo_fn in PHOTOS:
        photo = photo_fn()
        assert photo.face is not None
        fw = (photo.face[2] - photo.face[0])
        fh = (photo.face[3] - photo.face[1])
        for z in (0.8, 1.4, 2.2):
            s = scale_at(photo, z)
            w, h = fw * s, fh * s
            for edge in ("left", "right", "top", "bottom"):
                for along in (0.3, 0.7):
                    a = along + float(rng.uniform(-0.08, 0.08))
                    if edge == "left":
                        bx, by = w / 2 - fraction * w, a * HEIGHT
                    elif edge == "right":
                        bx, by = WIDTH - w / 2 + fraction * w, a * HEIGHT
                    elif edge == "top":
                        bx, by = a * WIDTH, h / 2 - fraction * h
                    else:
                        bx, by = a * WIDTH, HEIGHT - h / 2 + fraction * h
                    img, box = place_face(backdrop(k), photo, z, bx, by)
                    out.append(HardScene(f"edge{round(fraction * 100)}",
                                         f"{photo.name} {z:.1f}m {edge} {a:.2f} bg{k % 6}",
                                         img, (box,)))
                    k += 1
    return out


def edge25() -> list[HardScene]:
    """A quarter of the face box outside the frame (each edge), 48 scenes."""
    return _edge(0.25, seed=13)


def edge50() -> list[HardScene]:
    """Half of the face box outside the frame (each edge), 48 scenes."""
    return _edge(0.5, seed=14)


def two() -> list[HardScene]:
    """Both photos in one frame at different distances and sides, 12 scenes (24 faces)."""
    pairs = [(0.9, 1.6), (1.6, 0.9), (1.2, 2.4), (2.4, 1.2), (2.0, 2.0), (1.0, 3.0)]
    rng = np.random.default_rng(15)
    out = []
    k = 0
    for za, zg in pairs:
        for left_is_astronaut in (True, False):
            v1, v2 = float(rng.uniform(170, 310)), float(rng.uniform(170, 310))
            ua, ug = (170.0, 470.0) if left_is_astronaut else (470.0, 170.0)
            img, box_a = place_face(backdrop(k), astronaut(), za, ua, v1)
            img, box_g = place_face(img, grace_hopper(), zg, ug, v2)
            out.append(HardScene("two", f"astronaut {za:.1f}m + grace_hopper {zg:.1f}m bg{k % 6}",
                                 img, (box_a, box_g)))
            k += 1
    return out


def _degraded(family: str, seed: int, spots: int,
              effects: list[tuple[str, Callable[[np.ndarray, np.random.Generator], np.ndarray]]],
              ) -> list[HardScene]:
    """Each photo at 1.0, 1.8 and 2.6 m at `spots` places per effect, the effect applied to
    the whole frame (as a camera would)."""
    rng = np.random.default_rng(seed)
    out = []
    k = 0
    for label, effect in effects:
        for photo_fn in PHOTOS:
            photo = photo_fn()
            for z in (1.0, 1.8, 2.6):
                for i in range(spots):
                    u, v = GRID[(k * 4 + i) % len(GRID)]
                    bx, by = _jitter(rng, u, v)
                    img, box = place_face(backdrop(k), photo, z, bx, by)
                    out.append(HardScene(family, f"{photo.name} {z:.1f}m {label} bg{k % 6}",
                                         effect(img, rng), (box,)))
                    k += 1
    return out


def underexposed(img: np.ndarray, rng: np.random.Generator, gain: float,
                 gamma: float) -> np.ndarray:
    """A low-light frame: less light on the sensor (`gain` on linear intensity, gamma
    `gamma`), then read noise, then rounding to 8 bits (which crushes the shadows)."""
    linear = (img.astype(np.float32) / 255.0) ** gamma * gain
    dark = linear ** (1.0 / gamma) * 255.0 + rng.normal(0.0, 2.5, img.shape)
    return np.clip(dark, 0, 255).astype(np.uint8)


def dark() -> list[HardScene]:
    """Under-exposed by 4x and 10x (linear light), with sensor noise, 36 scenes."""
    return _degraded("dark", 16, 3, [
        ("1/4 light", lambda img, rng: underexposed(img, rng, 0.25, 2.2)),
        ("1/10 light", lambda img, rng: underexposed(img, rng, 0.10, 2.2)),
    ])


def motion_blur(img: np.ndarray, length: int, angle_deg: float) -> np.ndarray:
    """A straight smear `length` px long at `angle_deg` (the head or camera moving)."""
    k = np.zeros((length, length), np.float32)
    c = (length - 1) / 2
    dx, dy = np.cos(np.radians(angle_deg)) * c, np.sin(np.radians(angle_deg)) * c
    cv2.line(k, (round(c - dx), round(c - dy)), (round(c + dx), round(c + dy)), 1.0, 1)
    return cv2.filter2D(img, -1, k / k.sum())


def defocus(img: np.ndarray, radius: int) -> np.ndarray:
    """An out-of-focus lens: a uniform disk kernel of `radius` px."""
    k = np.zeros((2 * radius + 1, 2 * radius + 1), np.float32)
    cv2.circle(k, (radius, radius), radius, 1.0, -1)
    return cv2.filter2D(img, -1, k / k.sum())


def motion() -> list[HardScene]:
    """Motion blur 9 px (any angle) and 15 px (horizontal), 36 scenes."""
    return _degraded("motion", 17, 3, [
        ("smear 9px", lambda img, rng: motion_blur(img, 9, float(rng.uniform(0, 180)))),
        ("smear 15px", lambda img, rng: motion_blur(img, 15, 0.0)),
    ])


def defocused() -> list[HardScene]:
    """Defocus with disk radius 3 and 5 px, 36 scenes."""
    return _degraded("defocus", 18, 3, [
        ("disk r3", lambda img, rng: defocus(img, 3)),
        ("disk r5", lambda img, rng: defocus(img, 5)),
    ])


def jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    assert out is not None
    return out


def jpeg20() -> list[HardScene]:
    """Frames through JPEG quality 20 (blocking and smeared colour), 36 scenes."""
    return _degraded("jpeg20", 19, 6, [("q20", lambda img, rng: jpeg(img, 20))])


FAMILIES: dict[str, Callable[[], list[HardScene]]] = {
    "far": far, "small": small, "edge25": edge25, "edge50": edge50, "two": two,
    "dark": dark, "motion": motion, "defocus": defocused, "jpeg20": jpeg20,
}
"""Scene family -> its scenes (built on call; ~30-90 MB each, so one at a time)."""


class _Noise:
    """Camera noise for sequences: a few fixed Gaussian fields (sd 3) used in turn, so
    consecutive frames differ like real ones without drawing 900k numbers per frame."""

    def __init__(self, seed: int, fields: int = 4) -> None:
        rng = np.random.default_rng(seed)
        self.fields = [np.round(rng.normal(0.0, 3.0, (HEIGHT, WIDTH, 3))).astype(np.int16)
                       for _ in range(fields)]

    def __call__(self, img: np.ndarray, i: int) -> np.ndarray:
        return np.clip(img + self.fields[i % len(self.fields)], 0, 255).astype(np.uint8)


def walk(photo: Photo, frames: int = 150, seed: int = 20) -> Sequence:
    """A person walking from 0.6 m out to 4.0 m and back (distance linear in time, 5 s at
    30 fps) while drifting across the frame, with camera noise on every frame."""
    noise = _Noise(seed)
    base = backdrop(seed)

    def render(i: int) -> tuple[np.ndarray, Box]:
        t = i / (frames - 1)
        z = 0.6 + 3.4 * (1.0 - abs(2.0 * t - 1.0))
        u = WIDTH / 2 + 170 * np.sin(2 * np.pi * t * 1.3)
        v = HEIGHT / 2 + 60 * np.sin(2 * np.pi * t * 0.7)
        img, box = place_face(base, photo, z, u, v)
        return noise(img, i), box

    return Sequence(f"walk {photo.name}", frames, render)


def leave(photo: Photo, edge: str, frames: int = 30, z_m: float = 1.2,
          seed: int = 21) -> Sequence:
    """A person at `z_m` sliding from fully in view to 60% outside `edge` in one second."""
    assert photo.face is not None
    s = scale_at(photo, z_m)
    w, h = (photo.face[2] - photo.face[0]) * s, (photo.face[3] - photo.face[1]) * s
    noise = _Noise(seed)
    base = backdrop(seed)

    def render(i: int) -> tuple[np.ndarray, Box]:
        out = -0.2 + 0.8 * i / (frames - 1)  # fraction of the box outside: -0.2 .. 0.6
        bx, by = {
            "left": (w / 2 - out * w, HEIGHT * 0.45),
            "right": (WIDTH - w / 2 + out * w, HEIGHT * 0.55),
            "top": (WIDTH * 0.4, h / 2 - out * h),
            "bottom": (WIDTH * 0.6, HEIGHT - h / 2 + out * h),
        }[edge]
        img, box = place_face(base, photo, z_m, bx, by)
        return noise(img, i), box

    return Sequence(f"leave {edge} {photo.name}", frames, render)


SEQUENCE_KINDS = ("walk", "leave")


def sequences(kind: str | None = None) -> Iterator[Sequence]:
    """The service-path sequences (`kind` "walk" or "leave", None: both): each photo
    walking 0.6-4 m and back, and each photo leaving by each edge."""
    if kind in (None, "walk"):
        for photo_fn in PHOTOS:
            yield walk(photo_fn())
    if kind in (None, "leave"):
        for photo_fn in PHOTOS:
            for edge in ("left", "right", "top", "bottom"):
                yield leave(photo_fn(), edge)


def matches(found: Box, true: Box) -> bool:
    """A detection counts for a true face when the boxes overlap by IoU >= 0.3 or the
    detection's centre lies inside the true box. Faces leaving the frame are boxed by
    detectors in different ways (clipped or extrapolated), so the centre test keeps
    either convention from being punished; 0.3 tolerates the size differences between
    box conventions on a 20 px face."""
    cx, cy = (found[0] + found[2]) / 2, (found[1] + found[3]) / 2
    return iou(found, true) >= 0.3 or (true[0] <= cx <= true[2] and true[1] <= cy <= true[3])


def found_count(detections: list[Box], truths: tuple[Box, ...]) -> int:
    """How many true faces have a detection (each detection used for at most one face)."""
    left = list(detections)
    n = 0
    for true in truths:
        for i, d in enumerate(left):
            if matches(d, true):
                n += 1
                del left[i]
                break
    return n


def service_pipeline(settings: FaceDetectorSettings | None = None,
                     net: FaceNet | None = None) -> FacePipeline:
    """`FacePipeline` as `face-detector` builds it from `settings` (default: the service's
    defaults, so the figures follow the default model when it changes): the configured
    model at its threshold (or `net`, that network already loaded), and the short-range
    refiner when refinement is on."""
    s = settings or FaceDetectorSettings()
    net = net or FaceNet(models.locate(s.model), bf.SPECS[s.model], s.min_score)
    return FacePipeline(net, s, load_refiner(net, s))


def published_box(r: FaceResult) -> Box | None:
    """The box of the face whose position the service published (None: nothing was)."""
    if r.point is None:
        return None
    det = r.measured if r.measured is not None else r.target
    return None if det is None else (float(det.box[0]), float(det.box[1]),
                                     float(det.box[2]), float(det.box[3]))
