"""Identity service figures: match time for 10,000 people, frames to a name, accepts, memory,
and the face detector's latency with and without identity running.

    .venv/bin/python benchmarks/identity_service.py [--people 10000] [--seconds 20]

* match: one probe against N people of 1 and of 16 embeddings each (random
  unit vectors), `matching.Index` (NumPy) against the plain Python loop
  `best_match` was before; and the time to build the index.
* names: a router and `buddybot run identity` with its default settings
  (every 3rd frame, 3 of the last 5 answers agree); real photos fed as the
  camera and face-detector publish them (tests/identity/feed.py, 30
  frames/s). Obama is enrolled from one photo, Biden and Eileen Collins from
  theirs; then two other photos of Obama (true accepts expected) and Grace
  Hopper (never enrolled) are shown, each as a new track, and with Obama
  forgotten the two Obama photos again (must stay unknown). Frames from the
  first frame of a track to its name; the identity process's RSS.
* gaze: `camera --sim` (30 frames/s) and `face-detector` as processes, the
  latency of `camera/front/face` (stamp to arrival) for `--seconds`, first
  alone, then with `identity` running on a gallery holding someone else, so
  that it embeds the simulated face every 3rd frame all along (its worst
  case: an undecided track is never named).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks import results  # noqa: E402
from benchmarks.common import percentile  # noqa: E402
from buddybot.contract import keys  # noqa: E402
from buddybot.contract import messages as m  # noqa: E402
from buddybot.identity import embedding, gallery, matching  # noqa: E402
from buddybot.runtime.node import Node  # noqa: E402
from buddybot.tools.testing import Collector, Process, Router, retry_until, run_service  # noqa: E402


def loop_match(probe: np.ndarray, names: list[str], rows: np.ndarray) -> tuple[str, float]:
    """The per-person loop `best_match` used before the index (the reference time)."""
    best_of: dict[str, float] = {}
    for name, score in zip(names, (rows @ probe).tolist(), strict=True):
        best_of[name] = max(score, best_of.get(name, -1.0))
    ranked = sorted(best_of.items(), key=lambda kv: kv[1], reverse=True)
    return ranked[0]


def match_speed(people: int, repeat: int = 50) -> None:
    rng = np.random.default_rng(0)
    for per in (1, 16):
        names = [f"person {i}" for i in range(people) for _ in range(per)]
        rows = rng.normal(size=(len(names), embedding.DIM)).astype(np.float32)
        rows /= np.linalg.norm(rows, axis=1, keepdims=True)
        t0 = time.perf_counter()
        index = matching.Index.build(names, rows)
        build_ms = (time.perf_counter() - t0) * 1e3
        probe = rows[len(rows) // 2]
        fast, slow = [], []
        for _ in range(repeat):
            t0 = time.perf_counter()
            index.match(probe)
            fast.append((time.perf_counter() - t0) * 1e3)
        for _ in range(max(5, repeat // 10)):
            t0 = time.perf_counter()
            loop_match(probe, names, rows)
            slow.append((time.perf_counter() - t0) * 1e3)
        print(f"match against {people} people x {per} embeddings ({len(rows)} rows): "
              f"index median {statistics.median(fast):.2f} ms (p95 {percentile(fast, 95):.2f}), "
              f"Python loop median {statistics.median(slow):.1f} ms; index build {build_ms:.0f} ms")


def wait_served(probe: Node) -> None:
    retry_until(lambda: any(i.node == "identity" and "identity/enrol" in i.services
                            and "camera/front/faces" in i.subscriptions
                            for i in probe.node_infos(1.0)), 60, 0.2, "identity up")


def names(folder: Path) -> None:
    from tests.identity.feed import Camera, scene
    from tests.identity.photos import detectors, photos

    nets = detectors()
    shots = {p.name: scene(nets, p) for p in photos()}
    config = folder / "robot.toml"
    config.write_text(f'[identity]\ngallery = "{folder / "gallery.bin"}"\nlost_s = 0.3\n')
    router = Router(log_dir=folder)
    probe = Node("bench", connect=[router.endpoint])
    proc = run_service("identity", router.endpoint, "--config", str(config), log_dir=folder)
    camera = Camera(probe, period_s=1 / 30)
    said = Collector[m.FaceName](probe, keys.FACE_NAME, camera="front")
    try:
        wait_served(probe)
        for name, photo in (("Obama", "obama"), ("Biden", "biden"), ("Collins", "astronaut")):
            camera.show(shots[photo])
            reply = probe.call(keys.IDENTITY_ENROL, m.EnrolRequest(name=name), timeout=60.0)
            print(f"  enrol {name} from {photo}: {reply.message}")
        frames: list[int] = []
        true_accepts = false_accepts = trials_known = trials_unknown = 0

        def trial(photo: str, expected: str | None, seconds: float = 6.0) -> None:
            nonlocal true_accepts, false_accepts, trials_known, trials_unknown
            camera.show(None)
            retry_until(lambda: said.messages and said.messages[-1].track is None, 10, 0.02)
            start = len(said.messages)
            camera.show(shots[photo])
            deadline = time.monotonic() + seconds
            got: m.FaceName | None = None
            while time.monotonic() < deadline and got is None:
                got = next((n for n in said.messages[start:] if n.name is not None), None)
                time.sleep(0.02)
            if expected is None:
                trials_unknown += 1
            else:
                trials_known += 1
            if got is None:
                print(f"  {photo}: unknown for {seconds:.0f} s (expected {expected})")
                return
            if got.name == expected:
                true_accepts += 1
                frames.append(camera.frames_until(got.stamp_ns))
            else:
                false_accepts += 1
            print(f"  {photo}: {got.name} after {camera.frames_until(got.stamp_ns)} frames "
                  f"(score {got.score:.3f}; expected {expected})")

        for photo in ("obama2", "obama3", "obama2", "obama3"):
            trial(photo, "Obama")
        trial("grace_hopper", None)
        rss = psutil.Process(proc.pid).memory_info().rss / 2**20
        probe.call(keys.IDENTITY_FORGET, m.ForgetRequest(name="Obama"))
        for photo in ("obama2", "obama3"):
            trial(photo, None)
        print(f"names (default vote, 30 frames/s): true accepts {true_accepts}/{trials_known}, "
              f"false accepts {false_accepts}/{trials_known + trials_unknown}; frames from "
              f"first sight to the name: median {statistics.median(frames) if frames else 0:.0f}"
              f" (min {min(frames, default=0)}, max {max(frames, default=0)}); "
              f"identity process RSS {rss:.0f} MB")
    finally:
        camera.close()
        probe.close()
        proc.stop()
        router.stop()


def face_latency(folder: Path, seconds: float, with_identity: bool) -> tuple[list[float], str]:
    """Stamp-to-arrival latency of camera/front/face, ms, and a note on identity."""
    path = folder / ("with.bin" if with_identity else "without.bin")
    g = gallery.Gallery(embedding.MODEL_ID)
    g.enrol("somebody else", [embedding.unit(np.random.default_rng(1).normal(
        size=embedding.DIM))], time.time())
    gallery.save(path, g, gallery.load_key(gallery.key_path())[0])
    config = folder / "gaze.toml"
    config.write_text(f'[identity]\ngallery = "{path}"\n')
    router = Router(log_dir=folder)
    probe = Node("bench", connect=[router.endpoint])
    latencies: list[float] = []
    lock = threading.Lock()

    def on_face(msg: m.FacePosition, _key: str) -> None:
        with lock:
            latencies.append((m.now_ns() - msg.stamp_ns) / 1e6)

    diag = Collector[m.DiagnosticStatus](probe, keys.DIAGNOSTICS, node="identity")
    probe.subscribe(keys.FACE, on_face, camera="front")
    procs: list[Process] = [
        run_service("camera", router.endpoint, "--sim", log_dir=folder),
        run_service("face-detector", router.endpoint, log_dir=folder)]
    if with_identity:
        procs.append(run_service("identity", router.endpoint, "--config", str(config),
                                 log_dir=folder))
    note = "identity not running"
    try:
        retry_until(lambda: len(latencies) >= 30, 90, 0.2, "faces")
        if with_identity:
            wait_served(probe)
            retry_until(lambda: any(int(d.values.get("embeddings", 0)) > 0
                                    for d in diag.messages), 60, 0.2, "identity embedding")
        with lock:
            latencies.clear()
        first = [int(d.values.get("embeddings", 0)) for d in diag.messages][-1:] or [0]
        time.sleep(seconds)  # a measurement window, not a synchronisation
        with lock:
            got = sorted(latencies)
        if with_identity:
            last = int(diag.messages[-1].values.get("embeddings", 0))
            ident = next(p for p in procs if "identity" in p.name)
            cpu = psutil.Process(ident.pid).cpu_times()
            note = (f"identity embedded ~{(last - first[0]) / seconds:.1f} faces/s, "
                    f"CPU {cpu.user + cpu.system:.1f} s total, "
                    f"RSS {psutil.Process(ident.pid).memory_info().rss / 2**20:.0f} MB")
    finally:
        probe.close()
        for proc in procs:
            proc.stop()
        router.stop()
    return got, note


def gaze(folder: Path, seconds: float) -> None:
    for with_identity in (False, True):
        got, note = face_latency(folder, seconds, with_identity)
        if not got:
            print("gaze: no faces received")
            continue
        print(f"camera/front/face latency {'with' if with_identity else 'without'} identity: "
              f"{len(got) / seconds:.1f} faces/s, median {statistics.median(got):.1f} ms, "
              f"p95 {percentile(got, 95):.1f} ms (load average {os.getloadavg()[0]:.1f}; "
              f"{note})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--people", type=int, default=10_000)
    parser.add_argument("--seconds", type=float, default=20.0,
                        help="face latency window, each run")
    parser.add_argument("--only", choices=("match", "names", "gaze"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="identity-bench-") as tmp:
        if args.only in (None, "match"):
            match_speed(args.people)
        if args.only in (None, "names"):
            names(Path(tmp))
        if args.only in (None, "gaze"):
            gaze(Path(tmp), args.seconds)


if __name__ == "__main__":
    raise SystemExit(results.run(__file__, main))
