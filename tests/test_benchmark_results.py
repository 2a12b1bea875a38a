"""Benchmark figures live in benchmarks/RESULTS.md, written by the scripts.

`benchmarks/results.py` (the scripts' shared helper) replaces one script's
section with the output of its last run, dated, with the machine; every
benchmark script ends through it, and the page holds only sections of
scripts that exist.
"""

from __future__ import annotations

import datetime
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import results  # noqa: E402

HELPERS = {"__init__", "common", "results", "remote_page"}
"""Modules of benchmarks/ that are not benchmarks (remote_page: a helper page driver)."""
WHEN = datetime.datetime(2026, 1, 2, 3, 4, tzinfo=datetime.UTC)


def test_a_run_replaces_its_own_section_only() -> None:
    page = results.merged("", "radar", results.section("radar", [], "old radar\n", WHEN, "m1"))
    page = results.merged(page, "audio", results.section("audio", ["--n", "3"], "a\n", WHEN,
                                                         "m1"))
    page = results.merged(page, "radar", results.section("radar", [], "new radar\n", WHEN,
                                                         "m2"))
    assert page.startswith(results.HEADER)
    assert "old radar" not in page and "new radar" in page and "\na\n" in page
    assert page.index("benchmarks/audio.py") < page.index("benchmarks/radar.py")
    assert "Run 2026-01-02 03:04 UTC on m1: `benchmarks/audio.py --n 3`" in page
    assert set(results.sections(page)) == {"audio", "radar"}


def test_run_records_a_success_and_not_a_failure(tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    page = tmp_path / "RESULTS.md"
    monkeypatch.setattr(results, "RESULTS", page)
    monkeypatch.setattr(sys, "argv", ["benchmarks/fake.py", "--count", "2"])
    assert results.run("benchmarks/fake.py", lambda: print("median 1.0 ms")) == 0
    text = page.read_text()
    assert "median 1.0 ms" in text and "`benchmarks/fake.py --count 2`" in text
    assert " cores, " in text  # the machine

    def failing() -> int:
        print("median 9.9 ms")
        return 1

    assert results.run("benchmarks/fake.py", failing) == 1
    monkeypatch.setattr(sys, "argv", ["benchmarks/fake.py", results.NO_RECORD])
    assert results.run("benchmarks/fake.py", lambda: print("median 7.7 ms")) == 0
    assert page.read_text() == text


def scripts() -> list[str]:
    return sorted(p.stem for p in BENCHMARKS.glob("*.py") if p.stem not in HELPERS)


@pytest.mark.parametrize("script", scripts())
def test_every_benchmark_records_its_figures(script: str) -> None:
    assert "results.run(__file__, main)" in (BENCHMARKS / f"{script}.py").read_text()


def test_the_page_holds_only_existing_scripts() -> None:
    found = results.sections((BENCHMARKS / "RESULTS.md").read_text())
    assert found and set(found) <= set(scripts())
