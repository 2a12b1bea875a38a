"""Tests of the simulated world; `SCENARIOS` holds the tests' own scenario files."""

from pathlib import Path

SCENARIOS = Path(__file__).resolve().parent / "scenarios"
