"""The CPU report of a test run: sums by file, heaviest tests first."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cpu_usage import summary

LINES: list[dict[str, object]] = [
    {"test": "tests/a/test_x.py::test_one", "wall_s": 2.0, "cpu_s": 1.0, "children_cpu_s": 3.0},
    {"test": "tests/a/test_x.py::test_two", "wall_s": 1.0, "cpu_s": 0.5, "children_cpu_s": 0.0},
    {"test": "tests/b/test_y.py::test_three", "wall_s": 9.0, "cpu_s": 2.0, "children_cpu_s": 0.0},
]


def test_files_are_summed_and_ranked_by_cpu_with_children_counted() -> None:
    lines = summary(LINES, top=10).splitlines()
    assert lines[1].split() == ["4.5", "3.0", "2", "tests/a/test_x.py"]
    assert lines[2].split() == ["2.0", "9.0", "1", "tests/b/test_y.py"]
    assert lines[3].split() == ["6.5", "12.0", "3", "(all)"]
    tests = lines[lines.index("") + 2:]
    assert [t.split()[-1] for t in tests] == [
        "tests/a/test_x.py::test_one", "tests/b/test_y.py::test_three",
        "tests/a/test_x.py::test_two"]


def test_top_limits_each_table() -> None:
    lines = summary(LINES, top=1).splitlines()
    assert len(lines) == 1 + 1 + 1 + 1 + 1 + 1  # header, file, all, blank, header, test


BURN_TESTS = """
import subprocess, sys
import pytest

BURN = "import time\\nt = time.process_time()\\nwhile time.process_time() - t < {}: pass\\n"
KEEP = []


def test_child():
    subprocess.run([sys.executable, "-c", BURN.format(0.05)])


@pytest.mark.integration
def test_lives_on():  # a process that outlives the test (a browser): not reaped
    code = BURN.format(0.3) + "print('burnt', flush=True)\\ntime.sleep(60)"
    KEEP.append(subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE))
    assert KEEP[-1].stdout.readline() == b"burnt\\n"


def test_burn():
    sum(range(3_000_000))


def teardown_module():  # in the last test's protocol: the lived-on one is reaped after it
    for proc in KEEP:
        proc.kill()
        proc.wait()
"""


@pytest.mark.integration  # a pytest run in a child process
def test_a_run_with_the_variable_set_writes_a_line_per_test(tmp_path: Path) -> None:
    out = tmp_path / "cpu.jsonl"
    test = tmp_path / "test_burn.py"
    test.write_text(BURN_TESTS)
    root = Path(__file__).resolve().parent.parent
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "tests.cpu_usage",
         str(test)], cwd=root, capture_output=True, text=True, timeout=120,
        env={**os.environ, "BUDDYBOT_TEST_CPU": str(out)})
    assert run.returncode == 0, run.stdout + run.stderr
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    by_name = {x["test"].split("::")[-1]: x for x in lines}
    assert set(by_name) == {"test_burn", "test_child", "test_lives_on"}
    assert by_name["test_burn"]["cpu_s"] > 0.01
    assert by_name["test_child"]["children_cpu_s"] > 0.01
    assert by_name["test_lives_on"]["children_cpu_s"] >= 0.25  # read from /proc
