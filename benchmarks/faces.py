"""Face detector figures against MediaPipe: speed on one core, recall on hard scenes.

    .venv/bin/python benchmarks/faces.py [--frames 300] [--peer-python /tmp/mp-venv/bin/python]

The peer, Google MediaPipe's legacy face detection, cannot live in the
repo's virtualenv, so it runs in its own as a child process fed frames over
a pipe; both sides are pinned to the same core and timed the same way, on
fresh copies of the same frames, alternating. Sections: speed (whole-frame
detection and the service path), recall on the hard scenes of
tests/camera/scenes.py (the source of tests/camera/test_recall.py's
thresholds), distance accuracy, head turn, jitter, end to end; `--skip`
leaves any out.

Method in full: docs/camera.md, 'Method of benchmarks/faces.py'.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import results  # noqa: E402

from buddybot.camera import blazeface as bf  # noqa: E402
from buddybot.camera import frames as frames_mod  # noqa: E402
from buddybot.camera import models  # noqa: E402
from buddybot.camera.facenet import FaceNet  # noqa: E402
from buddybot.camera.settings import FaceDetectorSettings  # noqa: E402
from buddybot.camera.world_view import WorldCamera  # noqa: E402
from buddybot.contract import keys  # noqa: E402
from buddybot.contract import messages as m  # noqa: E402
from buddybot.sim import scenario, views, world  # noqa: E402
from tests.camera import scenes  # noqa: E402

PEER_SCRIPT = textwrap.dedent('''
    # Runs in MediaPipe's virtualenv. Requests on stdin, answers on stdout (see faces.py).
    import json, os, sys, time
    import cv2
    import numpy as np
    core = int(sys.argv[1])
    os.sched_setaffinity(0, {core})
    cv2.setNumThreads(1)
    import mediapipe as mp
    fd = mp.solutions.face_detection
    nets = {k: fd.FaceDetection(model_selection=k, min_detection_confidence=0.5)
            for k in (0, 1)}
    warm = np.zeros((480, 640, 3), np.uint8)
    for net in nets.values():
        net.process(warm)
    inp, out = sys.stdin.buffer, sys.stdout
    out.write("ready\\n")
    out.flush()
    while True:
        head = inp.readline()
        if not head:
            break
        req = json.loads(head)
        w, h = req["w"], req["h"]
        bgr = np.frombuffer(inp.read(w * h * 3), np.uint8).reshape(h, w, 3)
        t = time.perf_counter()
        res = nets[req["model"]].process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        ms = (time.perf_counter() - t) * 1000.0
        boxes = []
        for d in res.detections or []:
            b = d.location_data.relative_bounding_box
            boxes.append([b.xmin * w, b.ymin * h, (b.xmin + b.width) * w,
                          (b.ymin + b.height) * h, float(d.score[0])])
        out.write(json.dumps({"ms": ms, "boxes": boxes}) + "\\n")
        out.flush()
''')


class MediaPipePeer:
    """MediaPipe in its own virtualenv, one frame per request over a pipe."""

    def __init__(self, python: Path, core: int) -> None:
        env = {**os.environ, "OMP_NUM_THREADS": "1", "GLOG_minloglevel": "2",
               "TF_CPP_MIN_LOG_LEVEL": "2"}
        self.proc = subprocess.Popen([str(python), "-c", PEER_SCRIPT, str(core)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, env=env)
        assert self.proc.stdout is not None
        first = self.proc.stdout.readline().decode(errors="replace")
        if first.strip() != "ready":
            self.proc.kill()
            raise RuntimeError(f"MediaPipe peer did not start ({python}): {first!r}")
        self.version = subprocess.run(
            [str(python), "-c", "import importlib.metadata as m; print(m.version('mediapipe'))"],
            capture_output=True, text=True, check=False).stdout.strip()

    def detect(self, bgr: np.ndarray, model: int) -> tuple[float, list[scenes.Box]]:
        """(milliseconds inside the peer, boxes in pixels) for one frame."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        h, w = bgr.shape[:2]
        head = json.dumps({"model": model, "w": w, "h": h}).encode() + b"\n"
        self.proc.stdin.write(head + np.ascontiguousarray(bgr).tobytes())
        self.proc.stdin.flush()
        answer = json.loads(self.proc.stdout.readline())
        return float(answer["ms"]), [tuple(b[:4]) for b in answer["boxes"]]

    def close(self) -> None:
        if self.proc.stdin:
            self.proc.stdin.close()
        try:
            self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def start_peer(args: argparse.Namespace) -> MediaPipePeer | None:
    python = Path(args.peer_python)
    if not python.exists():
        print(f"peer: NOT MEASURED (no MediaPipe virtualenv at {python}; see the docstring)")
        return None
    try:
        return MediaPipePeer(python, args.core)
    except RuntimeError as exc:
        print(f"peer: NOT MEASURED ({exc})")
        return None


def net_for(model: str) -> FaceNet:
    """A BlazeFace model at its spec's own threshold, as the service loads it by default."""
    return FaceNet(models.locate(model), bf.SPECS[model])


def ms_stats(ms: list[float]) -> tuple[float, float]:
    """(median, p95 by nearest rank)."""
    ordered = sorted(ms)
    return statistics.median(ordered), ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))]


def arrive(frame: np.ndarray) -> np.ndarray:
    """`frame` as face-detector gets it: a camera `Image` message encoded and decoded
    with the topic's codec (a fresh copy, warm in cache), like the peer's frame read
    from its pipe. Not timed: it is the transport's part of the latency."""
    codec = keys.CAMERA_IMAGE.codec
    h, w = frame.shape[:2]
    msg = m.Image(stamp_ns=1, frame_id="bench", width=w, height=h, encoding="bgr8",
                  data=frame.tobytes())
    return frames_mod.decode_image(codec.decode(codec.encode(msg), m.Image), w * h)


def speed(args: argparse.Namespace, peer: MediaPipePeer | None) -> None:
    """Whole-frame detection and the service path, frame by frame interleaved with the peer."""
    cam = WorldCamera(views.Lens(600.0, 600.0, 320.0, 240.0, 640, 480))
    visit = world.World(scenario.load("visit"))  # walking in, staying, walking away
    frames = [cam.frame(visit.at(i / 30.0 % 29.0)) for i in range(args.frames)]
    ours: dict[str, FaceNet] = {m: net_for(m) for m in ("full_sparse", "full", "short")}
    pipe = scenes.service_pipeline()
    times: dict[str, list[float]] = {k: [] for k in
                                     ("full_sparse", "full", "short", "mp1", "mp0", "service",
                                      "service_work")}
    found = dict.fromkeys(times, 0)

    def run_ours(name: str, f: np.ndarray) -> None:
        f = arrive(f)
        t = time.perf_counter()
        faces = ours[name].detect(f)
        times[name].append((time.perf_counter() - t) * 1000.0)
        found[name] += bool(faces)

    def run_peer(model: int, f: np.ndarray) -> None:
        assert peer is not None
        ms, boxes = peer.detect(f, model)
        times[f"mp{model}"].append(ms)
        found[f"mp{model}"] += bool(boxes)

    steps: list[Callable[[np.ndarray], None]] = [
        lambda f: run_ours("full_sparse", f), lambda f: run_ours("full", f),
        lambda f: run_ours("short", f)]
    if peer is not None:
        steps += [lambda f: run_peer(1, f), lambda f: run_peer(0, f)]
    for f in frames[:20]:  # warm-up, not counted
        for step in steps:
            step(f)
    for k in times:
        times[k].clear()
        found[k] = 0
    stamp = 0
    for i, f in enumerate(frames):
        order = steps if i % 2 == 0 else steps[::-1]
        for step in order:
            step(f)
        stamp += 33_333_333
        f = arrive(f)
        # As face-detector runs it: the face is published after `process`; the
        # whole-frame pass (every full_every_s) and the iris come after that.
        t = time.perf_counter()
        r = pipe.process(f, stamp, defer=True)
        t_out = time.perf_counter()
        pipe.run_owed(r.owed)
        t_done = time.perf_counter()
        times["service"].append((t_out - t) * 1000.0)
        times["service_work"].append((t_done - t) * 1000.0)
        found["service"] += r.point is not None
        found["service_work"] += r.point is not None

    print(f"speed: {len(frames)} simulated 640x480 frames, pinned to core {args.core} "
          f"(affinity {sorted(os.sched_getaffinity(0))}), cv2 threads {cv2.getNumThreads()}, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    rows = [
        ("ours: whole frame, full range sparse (default)", "full_sparse"),
        ("ours: whole frame, full range dense", "full"),
        ("MediaPipe: whole frame, full range (model 1)", "mp1"),
        ("ours: whole frame, short range", "short"),
        ("MediaPipe: whole frame, short range (model 0)", "mp0"),
        ("ours: service path, image in -> face out", "service"),
        ("ours: service work per frame (+ deferred pass)", "service_work"),
    ]
    print(f"  {'':<48} {'median ms':>9} {'p95 ms':>8}  faces in")
    for label, key in rows:
        if not times[key]:
            print(f"  {label:<48} {'not measured':>18}")
            continue
        med, p95 = ms_stats(times[key])
        print(f"  {label:<48} {med:9.2f} {p95:8.2f}  {found[key]}/{len(times[key])}")
    if peer is not None:
        for a, b, what in (("full_sparse", "mp1", "full range (sparse)"),
                           ("full", "mp1", "full range (dense)"), ("short", "mp0", "short range")):
            ratio = ms_stats(times[b])[0] / ms_stats(times[a])[0]
            print(f"  -> ours vs MediaPipe, {what}: {ratio:.2f}x its speed (median latency)")
    med = ms_stats(times["service"])[0]
    print(f"  -> service path median {med:.2f} ms (target < 2 ms)")


def recall(args: argparse.Namespace, peer: MediaPipePeer | None) -> None:
    """Recall of whole-frame detection per hard-scene family, and of the service path
    over sequences, ours and MediaPipe's on the same frames."""
    ours = {m: net_for(m) for m in ("full_sparse", "full", "short")}
    cols = ["full_sparse", "full", "short"] + (["mp1", "mp0"] if peer is not None else [])
    heads = {"full_sparse": "ours sparse", "full": "ours dense", "short": "ours short",
             "mp1": "MP full", "mp0": "MP short"}
    print("recall: true faces found / faces present (IoU >= 0.3 or detection centre inside "
          "the true box), whole frame; +N: detections not matched to a true face")
    print(f"  {'family':<9} {'faces':>5} " + " ".join(f"{heads[c]:>15}" for c in cols))
    for family, build in scenes.FAMILIES.items():
        hits = dict.fromkeys(cols, 0)
        false = dict.fromkeys(cols, 0)
        present = 0
        for sc in build():
            present += len(sc.boxes)
            for c in cols:
                if c.startswith("mp"):
                    assert peer is not None
                    boxes = peer.detect(sc.bgr, int(c[2]))[1]
                else:
                    boxes = [d.box for d in ours[c].detect(sc.bgr)]
                k = scenes.found_count(boxes, sc.boxes)
                hits[c] += k
                false[c] += len(boxes) - k
        print(f"  {family:<9} {present:>5} " + " ".join(
            f"{hits[c]:>4} ({hits[c] / present:4.0%}) +{false[c]:<2}" for c in cols))

    print("service path over sequences (30 fps): frames whose published face is the true "
          "one / frames (+N: frames publishing another place); MediaPipe: full range per frame")
    print(f"  {'sequence':<26} {'frames':>6} {'ours service':>17} {'ours sparse':>13}"
          f" {'MP full':>13}")
    totals = np.zeros(5, int)
    for seq in scenes.sequences():
        pipe = scenes.service_pipeline()
        svc = wrong = whole = mp = 0
        for i, (f, true) in enumerate(seq):
            box = scenes.published_box(pipe.process(f, (i + 1) * 33_333_333))
            if box is not None:
                hit = scenes.matches(box, true)
                svc += hit
                wrong += not hit
            whole += scenes.found_count([d.box for d in ours["full_sparse"].detect(f)], (true,))
            if peer is not None:
                mp += scenes.found_count(peer.detect(f, 1)[1], (true,))
        totals += (seq.length, svc, wrong, whole, mp)
        _service_row(seq.name, seq.length, svc, wrong, whole, mp if peer is not None else None)
    n, svc, wrong, whole, mp = (int(x) for x in totals)
    _service_row("all", n, svc, wrong, whole, mp if peer is not None else None)


def _service_row(name: str, n: int, svc: int, wrong: int, whole: int, mp: int | None) -> None:
    mp_cell = f"{mp:>4} ({mp / n:4.0%})" if mp is not None else "-"
    print(f"  {name:<26} {n:>6} {svc:>7} ({svc / n:4.0%}) +{wrong:<2} {whole:>6} ({whole / n:4.0%})"
          f" {mp_cell:>13}")


def accuracy() -> None:
    print("accuracy: distance / true distance over 9 positions (median [min..max]), fx=600")
    for photo_fn in (scenes.astronaut, scenes.grace_hopper):
        photo = photo_fn()
        for z in (0.6, 1.0, 1.8, 2.5, 3.0):
            cells = []
            for refine in (False, True):
                ratios = []
                for u in (200, 320, 440):
                    for v in (180, 240, 300):
                        img, _ = scenes.scene(photo, z, u, v)
                        pipe = scenes.service_pipeline(FaceDetectorSettings(smoothing=False,
                                                                     refine=refine))
                        r = pipe.process(img, 1)
                        if r.point is not None:
                            ratios.append(r.point[0] / z)
                if ratios:
                    cells.append(f"{statistics.median(ratios):.3f} [{min(ratios):.3f}.."
                                 f"{max(ratios):.3f}] n={len(ratios)}")
                else:
                    cells.append("no detection")
            print(f"  {photo.name:<12} {z:3.1f} m   full box: {cells[0]:<30} refined: {cells[1]}")


def turned(photo: scenes.Photo, yaw_deg: float) -> np.ndarray:
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
    print("head turn (synthetic cylinder warp), true distance 1.0 m: width cue / fused / "
          "estimated yaw")
    for photo_fn in (scenes.astronaut, scenes.grace_hopper):
        photo = photo_fn()
        cells = []
        for yaw in (0, 15, 30, 45):
            warped = scenes.Photo(photo.name, turned(photo, yaw), photo.right_pupil,
                                  photo.left_pupil, photo.face)
            img, _ = scenes.scene(warped, 1.0)
            r = scenes.service_pipeline(FaceDetectorSettings(smoothing=False)).process(img, 1)
            if r.point is None or r.estimate is None:
                cells.append(f"{yaw}deg: -")
                continue
            e = r.estimate
            cells.append(f"{yaw:2d}deg: {e.from_width_m:.3f}/{e.z_m:.3f}/"
                         f"{np.degrees(e.yaw_rad):4.1f}deg")
        print(f"  {photo.name:<12} " + "   ".join(cells))


def jitter() -> None:
    rng = np.random.default_rng(0)
    base, _ = scenes.scene(scenes.grace_hopper(), 1.5)
    frames = [np.clip(base + rng.normal(0, 6, base.shape), 0, 255).astype(np.uint8)
              for _ in range(90)]
    print("jitter: still face at 1.5 m, Gaussian pixel noise sd 6, 90 frames at 30 fps")
    for smoothing in (False, True):
        pipe = scenes.service_pipeline(FaceDetectorSettings(smoothing=smoothing))
        pts = np.array([p for i, f in enumerate(frames)
                        if (p := pipe.process(f, (i + 1) * 33_333_333).point) is not None])
        sd = pts[15:].std(axis=0) * 1000
        print(f"  smoothing {'on ' if smoothing else 'off'}: sd x {sd[0]:5.1f} mm, "
              f"y {sd[1]:5.1f} mm, z {sd[2]:5.1f} mm")


def end_to_end(seconds: float = 15.0) -> None:
    """Router + `camera --sim` + `face-detector` as processes (not pinned): capture-to-face
    latency seen by a subscriber, and the face rate."""
    import threading

    from buddybot.contract import keys
    from buddybot.contract import messages as m
    from buddybot.runtime.node import Node
    from buddybot.tools.testing import Router, run_service

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
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--frames", type=int, default=300,
                        help="simulated frames for the speed section (30 fps)")
    parser.add_argument("--peer-python", default="/tmp/mp-venv/bin/python",
                        help="python of the MediaPipe 0.10.21 virtualenv")
    parser.add_argument("--core", type=int, default=0, help="CPU core to pin to")
    parser.add_argument("--skip", nargs="*", default=[],
                        choices=["speed", "recall", "accuracy", "turn", "jitter", "e2e"])
    args = parser.parse_args()
    os.sched_setaffinity(0, {args.core})
    cv2.setNumThreads(1)
    print(f"load average before: {Path('/proc/loadavg').read_text().strip()}")
    peer = None
    if not {"speed", "recall"} <= set(args.skip):
        peer = start_peer(args)
        if peer is not None:
            print(f"peer: MediaPipe {peer.version} (legacy solutions) at {args.peer_python}")
    try:
        if "speed" not in args.skip:
            speed(args, peer)
        if "recall" not in args.skip:
            recall(args, peer)
    finally:
        if peer is not None:
            peer.close()
    if "accuracy" not in args.skip:
        accuracy()
    if "turn" not in args.skip:
        head_turn()
    if "jitter" not in args.skip:
        jitter()
    if "e2e" not in args.skip:
        end_to_end()
    print(f"load average after: {Path('/proc/loadavg').read_text().strip()}")


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
