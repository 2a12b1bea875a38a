"""Face identity figures: scores on real photos, time per face on one core, memory, gallery size.

    .venv/bin/python benchmarks/identity.py [--repeat 50] [--people 10000]

Photos: tests/identity/photos.py (fetched from the package index into a
cache on first use). Each photo's face is found by BlazeFace (full range,
then the short-range refiner, as face-detector does) and embedded twice:
"ours" aligns from BlazeFace's keypoints (`identity.embedding`), "dlib"
with dlib's own 5-point landmarks and `get_face_chip` (reference: how
good the network is with its own aligner). Scores are cosines between unit
vectors: same person on independent shots, same person on one shot
(crops), different people. Matching: leave-one-out, every photo probed
against a gallery of every other independent shot, with the accept rule of
`identity.matching`. Time: alignment and embedding per face, median and
p95, the process pinned to one core with one OpenCV thread. Memory: RSS
added by loading the model and the first embedding. Gallery: save and load
time of 10,000 people. (OpenCV's SFace is not measured: no
package on the reachable registries ships its ONNX file, docs/identity.md.)
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import results  # noqa: E402

from buddybot.identity import embedding, gallery, matching  # noqa: E402
from tests.identity.photos import Photo, detectors, keypoints, photos  # noqa: E402


def rss_mb() -> float:
    return psutil.Process().memory_info().rss / 2**20


def timed(fn, repeat: int) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """Median and p95 of `repeat` calls, in ms."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1000)
    times.sort()
    return statistics.median(times), times[int(0.95 * (len(times) - 1))]


def pair_scores(shots: list[Photo], vecs: dict[str, np.ndarray]) -> dict[str, list[float]]:
    kinds: dict[str, list[float]] = {"same person, other shot": [], "same person, same shot": [],
                                     "different people": []}
    for a, b in itertools.combinations(shots, 2):
        score = float(vecs[a.name] @ vecs[b.name])
        if a.person != b.person:
            kinds["different people"].append(score)
        elif a.source != b.source:
            kinds["same person, other shot"].append(score)
        else:
            kinds["same person, same shot"].append(score)
    return kinds


def leave_one_out(shots: list[Photo], vecs: dict[str, np.ndarray]) -> tuple[int, int, int, int]:
    """(probes whose person is enrolled, true accepts, false accepts, probes)."""
    enrolled_probes = true_accepts = false_accepts = 0
    for probe in shots:
        others = [p for p in shots if p.source != probe.source]
        answer = matching.best_match(vecs[probe.name], [p.person for p in others],
                                     np.stack([vecs[p.name] for p in others]))
        known = any(p.person == probe.person for p in others)
        enrolled_probes += known
        if answer.name is not None:
            if answer.name == probe.person:
                true_accepts += 1
            else:
                false_accepts += 1
                print(f"    FALSE ACCEPT: {probe.name} named {answer.name} ({answer.score:.3f})")
    return enrolled_probes, true_accepts, false_accepts, len(shots)


def report(label: str, shots: list[Photo], vecs: dict[str, np.ndarray]) -> None:
    print(f"\n{label}")
    for kind, scores in pair_scores(shots, vecs).items():
        if scores:
            print(f"  cosine, {kind:<24} min {min(scores):.3f}  max {max(scores):.3f}  "
                  f"(n={len(scores)})")
    known, ta, fa, n = leave_one_out(shots, vecs)
    print(f"  leave-one-out (threshold {matching.THRESHOLD}, margin {matching.MARGIN}): "
          f"{ta}/{known} true accepts, {fa}/{n} false accepts")


def dlib_reference(shots: list[Photo], net: embedding.Embedder) -> dict[str, np.ndarray]:
    import dlib  # type: ignore[import-not-found]
    predictor = dlib.shape_predictor(str(net.path.parent / "shape_predictor_5_face_landmarks.dat"))
    finder = dlib.get_frontal_face_detector()
    out = {}
    for p in shots:
        rgb = cv2.cvtColor(p.bgr, cv2.COLOR_BGR2RGB)
        rects = sorted(finder(rgb, 1), key=lambda r: -r.area())
        chip = dlib.get_face_chip(rgb, predictor(rgb, rects[0]), size=150, padding=0.25)
        out[p.name] = embedding.unit(net.net.compute_face_descriptor(chip))
    return out


def gallery_figures(count: int) -> None:
    rng = np.random.default_rng(0)
    g = gallery.Gallery(embedding.MODEL_ID)
    for i in range(count):
        g.enrol(f"person {i}", [embedding.unit(rng.normal(size=embedding.DIM))], now_s=0.0)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "gallery.bin"
        t = time.perf_counter()
        key = bytes(32)  # any key: the figures are of the file, not of keeping it
        gallery.save(path, g, key)
        save_ms = (time.perf_counter() - t) * 1000
        t = time.perf_counter()
        loaded = gallery.load(path, embedding.MODEL_ID, key)
        load_ms = (time.perf_counter() - t) * 1000
        names, vectors = loaded.table()
        t = time.perf_counter()
        index = matching.Index.build(names, vectors)
        build_ms = (time.perf_counter() - t) * 1000
        t = time.perf_counter()
        index.match(vectors[0])
        match_ms = (time.perf_counter() - t) * 1000
        size = path.stat().st_size
    print(f"\ngallery of {count} people: file {size / 1024:.0f} kB, save {save_ms:.0f} ms, "
          f"load {load_ms:.0f} ms, match index built in {build_ms:.0f} ms, one match against "
          f"all {match_ms:.2f} ms (benchmarks/identity_service.py: median of many)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=50)
    parser.add_argument("--people", type=int, default=gallery.MAX_PEOPLE)
    args = parser.parse_args()
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    cv2.setNumThreads(1)

    shots = photos()
    nets = detectors()
    kps = {p.name: keypoints(nets, p.bgr) for p in shots}
    independent = len({(p.person, p.source) for p in shots})
    print(f"{len(shots)} photos of {len({p.person for p in shots})} people, "
          f"{independent} independent shots; OpenCV {cv2.__version__}")

    before = rss_mb()
    t = time.perf_counter()
    net = embedding.Embedder.load()
    load_s = time.perf_counter() - t
    loaded = rss_mb()
    vecs = {p.name: net.face(p.bgr, kps[p.name]) for p in shots}
    used = rss_mb()
    size_mb = net.path.stat().st_size / 2**20
    print(f"\ndlib ResNet ({embedding.MODEL_ID}): file {size_mb:.1f} MB, load {load_s:.2f} s, "
          f"RSS +{loaded - before:.0f} MB loaded, +{used - before:.0f} MB after embedding")

    bgr, k = shots[0].bgr, kps[shots[0].name]
    chip = embedding.aligned_crop(bgr, k)
    med, p95 = timed(lambda: embedding.aligned_crop(bgr, k), args.repeat)
    print(f"  aligned crop per face: median {med:.2f} ms, p95 {p95:.2f} ms")
    med, p95 = timed(lambda: net.embed(chip), args.repeat)
    print(f"  embedding per face (one core): median {med:.1f} ms, p95 {p95:.1f} ms")

    report("ours: BlazeFace keypoints -> aligned crop -> dlib ResNet", shots, vecs)
    report("reference: dlib's own landmarks and chip -> dlib ResNet", shots,
           dlib_reference(shots, net))
    gallery_figures(args.people)


if __name__ == "__main__":
    sys.exit(results.run(__file__, main))
