"""Shared by the benchmark scripts: percentiles and the ping-pong payloads.

Scripts run as `python benchmarks/<name>.py`, so this folder is on
`sys.path` and they import it as `common`.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from tempfile import mkdtemp
from typing import Any

import psutil

from buddybot.contract import keys
from buddybot.contract import messages as m

# Payload kind -> (ping topic, pong topic, ping params, pong params)
ROUTES: dict[str, tuple[keys.Topic, keys.Topic, dict[str, str], dict[str, str]]] = {
    "small": (keys.EYE_CONTROL, keys.EYES_DIRECTION, {}, {}),
    "image": (keys.CAMERA_IMAGE, keys.DEBUG_IMAGE, {"camera": "ping"}, {"camera": "pong"}),
}


CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update"]
"""Headless Debian Chromium for the benchmarks that drive the eye page."""


def make_message(kind: str, i: int) -> m.Message:
    """A small control message, or a 640x480 bgr8 image (921,600 bytes)."""
    if kind == "small":
        return m.EyeControl(stamp_ns=i, yaw=0.1, pitch=-0.05, target_distance_cm=120.0)
    return m.Image(stamp_ns=i, frame_id="bench", width=640, height=480, encoding="bgr8",
                   data=bytes(640 * 480 * 3))


def reply_for(msg: Any) -> m.Message:
    """What an echo answers: direction for a control message, the image itself."""
    if isinstance(msg, m.EyeControl):
        return m.EyesDirection(stamp_ns=msg.stamp_ns, yaw=5.7, pitch=-2.9)
    return msg


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0..1) by nearest rank."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def summary(name: str, values_ms: list[float]) -> str:
    return (f"{name}: n={len(values_ms)} median={statistics.median(values_ms):.3f} ms "
            f"p99={percentile(values_ms, 0.99):.3f} ms max={max(values_ms):.3f} ms")


def host() -> str:
    """The machine the figures come from, and how busy it was (a shared machine's
    load moves latencies and CPU shares)."""
    load = " ".join(f"{x:.1f}" for x in psutil.getloadavg())
    return (f"host: {psutil.cpu_count()} cores, load average {load}, "
            f"Python {sys.version.split()[0]}")


def options(doc: str | None, parts: tuple[str, ...]) -> argparse.ArgumentParser:
    """The script's options: its docstring as the help, and `--skip PART` for
    each part it measures, to run the others alone."""
    made = argparse.ArgumentParser(description=doc,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    made.add_argument("--skip", choices=parts, action="append", default=[],
                      help="leave a part out (repeatable)")
    return made



@contextmanager
def services_up(names: tuple[str, ...], config: str, prefix: str) -> Iterator[str]:
    """A router and `buddybot run NAME` for each name, with `config` as their
    robot.toml, logs in a fresh temporary folder; yields the router's endpoint
    and stops everything after."""
    from buddybot.tools.testing import Router, run_service

    folder = Path(mkdtemp(prefix=prefix))
    path = folder / "robot.toml"
    path.write_text(config)
    router = Router(log_dir=folder)
    procs = [run_service(name, router.endpoint, "--config", str(path), log_dir=folder)
             for name in names]
    try:
        yield router.endpoint
    finally:
        for proc in procs:
            proc.stop()
        router.stop()


def best_parse_rate(make_parser: Any, data: bytes, n: int, chunk: int = 4096,
                    runs: int = 3) -> float:
    """Frames/s of the best of `runs` parses of `data` (n frames) fed in `chunk`-byte reads."""
    import time

    chunks = [data[i:i + chunk] for i in range(0, len(data), chunk)]
    best = 0.0
    for _ in range(runs):
        parser = make_parser()
        t0 = time.perf_counter()
        count = sum(len(parser.feed(c)) for c in chunks)
        dt = time.perf_counter() - t0
        assert count == n, (count, n)
        best = max(best, n / dt)
    return best
