"""Benchmark figures live in benchmarks/RESULTS.md, not in the guide.

The guide pages say what a benchmark measures, how to run it and its
target; the measured figures of a run (a pasted output block, a table of
runs) belong to the script's section of benchmarks/RESULTS.md, where the
script itself writes them with the date and the machine. docs/design.md
states targets and is checked the same way. One measured statistic in a
block is an example (a command's output line); two or more make a results
block.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([*(ROOT / "docs").rglob("*.md"), ROOT / "README.md", ROOT / "deploy" / "README.md"])
FIGURE = re.compile(r"\b(?:median|p50|p90|p95|p99)\b[\s=:]*\d[\d.,]*\s*(?:ms|us|µs|s)\b", re.I)
"""A measured statistic: "median 1.39 ms", "median=0.619 ms", "p95 16.80 ms"."""
STATISTIC = re.compile(r"\b(?:median|p50|p90|p95|p99|measured)\b", re.I)
MEASURE = re.compile(r"\d[\d.,]*\s*(?:ms|us|µs|frames/s|msg/s|MB/s|%)(?![\w/])")
"""A measured value: "4.4 ms", "211,318 frames/s", "2.7 / 4.8 %"."""
MOST = 1
PENDING: dict[str, str] = {}
"""Pages whose figures are still to move: strict, so the entry goes once they have."""


def blocks(text: str) -> list[tuple[int, list[str], bool]]:
    """(first line number, lines, whether a table) of each fenced block and each table."""
    found: list[tuple[int, list[str], bool]] = []
    fenced: list[str] | None = None
    table: list[str] = []
    start = 0
    for n, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("```"):
            if fenced is None:
                fenced, start = [], n
            else:
                found.append((start, fenced, False))
                fenced = None
            continue
        if fenced is not None:
            fenced.append(line)
        elif line.lstrip().startswith("|"):
            if not table:
                start = n
            table.append(line)
        elif table:
            found.append((start, table, True))
            table = []
    if table:
        found.append((start, table, True))
    return found


def is_results(lines: list[str], table: bool) -> bool:
    """Whether a block holds the figures of a run, more than one example line.

    More than MOST lines with a statistic and its value ("median 1.2 ms");
    or more than MOST lines with a measured value in a block that names a
    statistic: for a table, in its header row (a table of settings, whose
    header names none, may give values in ms); for a fenced block, anywhere.
    """
    if sum(bool(FIGURE.search(line)) for line in lines) > MOST:
        return True
    named = STATISTIC.search(lines[0] if table else "\n".join(lines))
    body = lines[2:] if table else lines
    return bool(named) and sum(bool(MEASURE.search(line)) for line in body) > MOST


def results_blocks(text: str) -> list[str]:
    """`line: first line` of each block holding the figures of a run."""
    return [f"{start}: {lines[0].strip()}" for start, lines, table in blocks(text)
            if lines and is_results(lines, table)]


@pytest.mark.parametrize("page", [
    pytest.param(page, marks=pytest.mark.xfail(reason=PENDING[name], strict=True))
    if (name := page.relative_to(ROOT).as_posix()) in PENDING else page
    for page in PAGES], ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_benchmark_figures_in_the_guide(page: Path) -> None:
    found = results_blocks(page.read_text())
    assert not found, ("benchmark figures in the guide (move them to the script's section of "
                       "benchmarks/RESULTS.md, keep the method and the target):\n"
                       + "\n".join(found))


@pytest.mark.parametrize("text", [
    "```\nframe time  median   16.70 ms   p95   16.80 ms\n"
    "update+draw median    0.10 ms   p95    0.30 ms\n```\n",
    "```text\nface: n=993 median=1.204 ms p99=24.914 ms\nprobe: n=1001 median=0.600 ms\n```\n",
    "| run | gaze |\n|---|---|\n| 1 | median 4.4 ms |\n| 2 | p95 6.7 ms |\n",
    "| run | gaze p95 closed | open |\n|---|---|---|\n"
    "| 1 | 4.4 ms | 4.6 ms |\n| 2 | 6.7 ms | 6.8 ms |\n",
    "```\nparser: 211,318 frames/s\nbridge: 15,413 frames/s\nlatency: median 0.82 ms\n```\n",
])
def test_a_results_block_is_caught(text: str) -> None:
    assert results_blocks(text)


@pytest.mark.parametrize("text", [
    "```\n$ buddybot bag play run/\nplayed 1586 messages; late vs schedule p50 0.31 ms\n```\n",
    "Target: median <= 150 ms, met; p95 under 10 ms.\nmedian 2 ms and p95 5 ms in prose.\n",
    "| key | default | note |\n|---|---|---|\n| `defer_after_ms` | `3.0` | p95 ~10 -> ~6 ms |\n"
    "| `period_ms` | `10` | the median wait is half a period |\n",
    "```toml\n[eyes]\nmedian_window = 5\np95_budget_ms = 10\n```\n",
])
def test_examples_and_targets_pass(text: str) -> None:
    assert not results_blocks(text)
