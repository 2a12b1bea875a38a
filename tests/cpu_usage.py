"""Where a run's CPU goes: each test's wall time and CPU seconds, its own
process's and those of the processes it started and waited for.

On a two-core machine a full run is bound by CPU, not by waiting, so the tests
worth making cheaper are those that burn the most, not the longest. Set
`BUDDYBOT_TEST_CPU=FILE` and every worker appends one JSON line per test to
FILE; `python -m tests.cpu_usage FILE` sums them by file and lists the
heaviest tests. A worker's own threads (an in-process router) count towards
the test that runs while they work; so does every process below the worker
that lives on between tests (a browser, its page processes), read from /proc.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path

import pytest

ENV = "BUDDYBOT_TEST_CPU"


def _cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


TICK_S = 1 / os.sysconf("SC_CLK_TCK")


def _descendants_cpu(root: int) -> float:
    """CPU seconds of the live processes below `root` and of the children they
    reaped (a browser's page processes come and go below it)."""
    parent: dict[int, int] = {}
    spent: dict[int, float] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat", "rb") as f:
                fields = f.read().rsplit(b")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        pid = int(entry.name)
        parent[pid] = int(fields[1])
        spent[pid] = sum(int(x) for x in fields[11:15]) * TICK_S  # utime stime cutime cstime
    below, total = {root}, 0.0
    changed = True
    while changed:
        changed = False
        for pid, ppid in parent.items():
            if ppid in below and pid not in below:
                below.add(pid)
                total += spent[pid]
                changed = True
    return total


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item) -> Iterator[None]:
    target = os.environ.get(ENV)
    if not target:
        yield
        return
    # Scanning /proc costs a few ms: only tests that start processes or a browser.
    tree = bool(item.get_closest_marker("integration") or item.get_closest_marker("browser"))
    me = os.getpid()
    wall, own, children = (time.monotonic(), _cpu(resource.RUSAGE_SELF),
                           _cpu(resource.RUSAGE_CHILDREN))
    live = _descendants_cpu(me) if tree else 0.0
    yield
    children = _cpu(resource.RUSAGE_CHILDREN) - children
    if tree:  # a child alive before and reaped since: its earlier part leaves `live` again
        children = max(0.0, children + _descendants_cpu(me) - live)
    line = json.dumps({
        "test": item.nodeid,
        "wall_s": round(time.monotonic() - wall, 3),
        "cpu_s": round(_cpu(resource.RUSAGE_SELF) - own, 3),
        "children_cpu_s": round(children, 3),
    })
    # One short write per line in append mode: lines of several workers do not mix.
    with open(target, "a", encoding="utf-8") as out:
        out.write(line + "\n")


def summary(lines: list[dict[str, object]], top: int) -> str:
    """A table by file (CPU, wall, tests), then the `top` tests by CPU."""
    by_file: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0.0])
    rows = []
    for entry in lines:
        test = str(entry["test"])
        cpu = float(entry["cpu_s"]) + float(entry["children_cpu_s"])  # type: ignore[arg-type]
        wall = float(entry["wall_s"])  # type: ignore[arg-type]
        total = by_file[test.split("::")[0]]
        total[0] += cpu
        total[1] += wall
        total[2] += 1
        rows.append((cpu, wall, test))
    out = [f"{'cpu s':>8} {'wall s':>8} {'tests':>5}  file"]
    ranked = sorted(by_file.items(), key=lambda kv: -kv[1][0])
    out += [f"{c:8.1f} {w:8.1f} {int(n):5d}  {f}" for f, (c, w, n) in ranked[:top]]
    cpu_all = sum(r[0] for r in rows)
    out.append(f"{cpu_all:8.1f} {sum(r[1] for r in rows):8.1f} {len(rows):5d}  (all)")
    out += ["", f"{'cpu s':>8} {'wall s':>8}  test"]
    out += [f"{c:8.1f} {w:8.1f}  {t}" for c, w, t in sorted(rows, reverse=True)[:top]]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", type=Path, help=f"the file {ENV} named")
    parser.add_argument("--top", type=int, default=30, help="rows per table")
    args = parser.parse_args()
    text = args.file.read_text(encoding="utf-8").splitlines()
    print(summary([json.loads(line) for line in text if line.strip()], args.top))


if __name__ == "__main__":
    main()
