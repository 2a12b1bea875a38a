"""Where the benchmark figures live: one section per script in RESULTS.md.

Every script ends in `results.run(__file__, main)`: it runs `main`, shows
its output as usual, and when `main` succeeds writes that output as the
script's section of `benchmarks/RESULTS.md`, with the date, the machine
and the command line, replacing the section of the last run. So the
figures on the page are always the last run's, from the script itself,
never copied by hand into a guide. `--no-record` (taken out of the
arguments before `main` sees them) leaves the page alone, for trial runs.
"""

from __future__ import annotations

import datetime
import io
import os
import platform
import re
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import psutil

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
NO_RECORD = "--no-record"
HEADER = """# Benchmark results

For builders who want to know how fast the robot is, and on what machine it was measured.

Each section below is written by its benchmark script when it runs
(`.venv/bin/python benchmarks/NAME.py`, see its docstring for what it measures;
`--no-record` runs it without touching this page), with the date, the machine and the
command line of that run. Do not edit the sections by hand: run the script again.
"""
_SECTION = re.compile(r"^## `benchmarks/([\w.]+)\.py`", re.M)


class _Tee(io.TextIOBase):
    """Writes to the terminal and keeps a copy."""

    def __init__(self, out: TextIO) -> None:
        self.out = out
        self.copy = io.StringIO()

    def write(self, text: str) -> int:
        self.copy.write(text)
        return self.out.write(text)

    def flush(self) -> None:
        self.out.flush()


def machine() -> str:
    """The CPU, its cores, the memory and how busy the machine was."""
    cpu = platform.processor() or platform.machine()
    try:
        info = Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        info = ""
    found = re.search(r"^model name\s*:\s*(.+)$", info, re.M)
    if found:
        cpu = found.group(1).strip()
    memory_gb = psutil.virtual_memory().total / 2**30
    load = " ".join(f"{x:.1f}" for x in psutil.getloadavg())
    return (f"{cpu}, {psutil.cpu_count()} cores, {memory_gb:.0f} GB, "
            f"{platform.system()} {platform.release()}, Python {platform.python_version()}, "
            f"load average {load} at the end")


def section(script: str, argv: list[str], output: str, when: datetime.datetime,
            where: str) -> str:
    command = " ".join([f"benchmarks/{script}.py", *argv])
    return (f"## `benchmarks/{script}.py`\n\n"
            f"Run {when:%Y-%m-%d %H:%M} UTC on {where}: `{command}`\n\n"
            f"```text\n{output.rstrip()}\n```\n")


def sections(text: str) -> dict[str, str]:
    """Script name -> its section, from the page's text."""
    starts = [(m.start(), m.group(1)) for m in _SECTION.finditer(text)]
    ends = [start for start, _ in starts[1:]] + [len(text)] if starts else []
    return {name: text[start:end].rstrip() + "\n"
            for (start, name), end in zip(starts, ends, strict=True)}


def merged(text: str, script: str, new: str) -> str:
    """The page with `script`'s section replaced by `new` (sections sorted by name)."""
    found = sections(text)
    found[script] = new
    return HEADER + "".join(f"\n{found[name]}" for name in sorted(found))


def record(script: str, argv: list[str], output: str, path: Path | None = None) -> None:
    path = path or RESULTS
    when = datetime.datetime.now(datetime.UTC)
    old = path.read_text() if path.is_file() else ""
    path.write_text(merged(old, script, section(script, argv, output, when, machine())))


def run(script_file: str, main: Callable[[], Any]) -> int:
    """Run a script's `main`, recording its output when it succeeds; its exit status."""
    record_it = NO_RECORD not in sys.argv
    if not record_it:
        sys.argv.remove(NO_RECORD)
    argv = sys.argv[1:]
    tee = _Tee(sys.stdout)
    sys.stdout = tee
    # The services a benchmark starts keep their state (the operator secret, the
    # gallery key) in a folder of the run's, never in the robot's own.
    state = tempfile.TemporaryDirectory(prefix="buddybot-bench-state-")
    before = os.environ.get("BUDDYBOT_STATE_DIR")
    os.environ["BUDDYBOT_STATE_DIR"] = state.name
    try:
        status = main()
    finally:
        sys.stdout = tee.out
        if before is None:
            os.environ.pop("BUDDYBOT_STATE_DIR", None)
        else:
            os.environ["BUDDYBOT_STATE_DIR"] = before
        state.cleanup()
    code = int(status or 0)
    if code == 0 and record_it and "--help" not in argv and "-h" not in argv:
        record(Path(script_file).stem, argv, tee.copy.getvalue())
        print(f"recorded in {os.path.relpath(RESULTS)}", file=sys.stderr)
    return code
