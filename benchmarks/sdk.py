"""SDK benchmark: the memory of an idle app. Prints figures.

    .venv/bin/python benchmarks/sdk.py [--settle-s 3]

1. Idle app memory: a program (its own process) connects a `Bot` to a real
   router on 127.0.0.1 with a `people` service, subscribes to the people
   events (`bot.on(...)`) and idles. Its VmRSS (/proc/<pid>/status) once
   it settled, and what it imported: the modules loaded, and whether a
   heavy one (numpy, cv2) came in through the runtime.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import psutil

from buddybot.tools.testing import Router, run_service

IDLE_APP = """
import sys

from buddybot.sdk import Bot

with Bot.connect(connect=[sys.argv[1]], timeout=30) as bot:
    bot.on(("ARRIVED", "ENGAGEMENT_CHANGED", "ZONE_CHANGED", "LEFT"), lambda event: None)
    heavy = sorted(name for name in ("numpy", "cv2", "PIL", "psutil") if name in sys.modules)
    print("ready", len(sys.modules), ",".join(heavy) or "-", flush=True)
    sys.stdin.read()  # idle until the benchmark closes our stdin
"""


def vm_rss_mb(pid: int) -> float:
    """VmRSS of a process, from /proc/<pid>/status."""
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmRSS for pid {pid}")


def bench_idle_rss(router: Router, settle_s: float) -> None:
    people = run_service("people", router.endpoint)
    app = subprocess.Popen([sys.executable, "-c", IDLE_APP, router.endpoint],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert app.stdout is not None
        line = app.stdout.readline().split()  # waits for the app (its connect is bounded)
        if not line or line[0] != "ready":
            raise RuntimeError(f"the idle app failed: {line}")
        modules, heavy = int(line[1]), line[2]
        time.sleep(settle_s)  # threads started, first samples in (not a synchronisation)
        rss = vm_rss_mb(app.pid)
    finally:
        if app.stdin is not None:
            app.stdin.close()
        app.wait(timeout=30)
        people.stop()
    print(f"idle app (Bot + bot.on people events), VmRSS after {settle_s:g} s: {rss:.1f} MB; "
          f"{modules} modules imported, heavy ones: {heavy}  (target: <= 45 MB)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--settle-s", type=float, default=3.0,
                        help="idle time before the app's RSS is read")
    args = parser.parse_args()
    print(f"host: {psutil.cpu_count()} cores, load average "
          f"{' '.join(f'{x:.1f}' for x in psutil.getloadavg())}, Python "
          f"{sys.version.split()[0]}")
    router = Router()
    try:
        bench_idle_rss(router, args.settle_s)
    finally:
        router.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
