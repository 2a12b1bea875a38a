"""The Hypothesis profiles: scaled counts, and no test that sets its own.

A literal `max_examples=400` would run 400 examples in `--quick` too, and a
per-test `deadline` or `too_slow` suppression would make a test's verdict
depend on the machine again; both are refused here.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from tests import properties

TESTS = Path(__file__).resolve().parent


@pytest.fixture
def profile() -> Iterator[None]:
    """Restore the run's profile after a test loads another one."""
    before = properties.current()
    yield
    settings.load_profile(before)


@pytest.mark.parametrize(("name", "full", "want"), [
    ("quick", 400, 40), ("quick", 50, 10), ("full", 400, 400), ("nightly", 400, 4000),
])
def test_a_profile_scales_the_full_count(profile: None, name: str, full: int,
                                         want: int) -> None:
    settings.load_profile(name)
    assert properties.examples(full) == want


@pytest.mark.parametrize("name", sorted(properties.SCALE))
def test_no_profile_measures_the_machine(name: str) -> None:
    chosen = settings.get_profile(name)
    assert chosen.deadline is None
    assert HealthCheck.too_slow in chosen.suppress_health_check


def own_settings(path: Path, root: Path = TESTS) -> Iterator[str]:
    """`file:line what` for each settings(...) call that fixes what profiles decide."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not (isinstance(node, ast.Call) and getattr(node.func, "id", "") == "settings"):
            continue
        for kw in node.keywords:
            literal = kw.arg == "max_examples" and isinstance(kw.value, ast.Constant)
            if literal or kw.arg in ("deadline", "suppress_health_check"):
                yield f"{path.relative_to(root)}:{node.lineno} {kw.arg}"


def test_no_test_sets_what_the_profiles_decide() -> None:
    found = [hit for path in sorted(TESTS.rglob("*.py")) if path.name != "properties.py"
             for hit in own_settings(path)]
    assert not found, "use max_examples=examples(N) and the profiles' deadline:\n" + \
        "\n".join(found)


def test_the_check_finds_a_literal_count(tmp_path: Path) -> None:
    planted = tmp_path / "x.py"
    planted.write_text("@settings(max_examples=400, deadline=None)\ndef f(): ...\n"
                       "@settings(max_examples=examples(400))\ndef g(): ...\n")
    assert list(own_settings(planted, tmp_path)) == ["x.py:1 max_examples", "x.py:1 deadline"]
