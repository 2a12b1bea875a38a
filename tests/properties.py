"""How hard the property tests try: one Hypothesis profile per kind of run.

A test states its example count for the full run through `examples(n)`; the
profile scales it: `quick` (scripts/test.sh --quick) a tenth, `full` (the
README's test command) as written, `nightly` ten times. No profile has a
deadline or the `too_slow` health check: both measure the machine, not the
code, and fail on a busy one. Choose with `--hypothesis-profile NAME`.
"""

from __future__ import annotations

from hypothesis import HealthCheck, settings

SCALE = {"quick": 0.1, "full": 1.0, "nightly": 10.0}
"""Profile -> factor applied to each test's full-run example count."""
DEFAULT = "full"
FLOOR = 10
"""No property runs fewer examples than this, however small the profile."""
BASE_EXAMPLES = 100
"""Hypothesis's own default count, the `full` profile's for tests that name none."""


def register() -> None:
    """Register every profile and load the full one (the command line may override)."""
    for name, scale in SCALE.items():
        settings.register_profile(
            name, max_examples=max(FLOOR, round(BASE_EXAMPLES * scale)), deadline=None,
            suppress_health_check=[HealthCheck.too_slow], print_blob=True)
    settings.load_profile(DEFAULT)


def current() -> str:
    """The loaded profile's name (told apart by its example count)."""
    return min(SCALE, key=lambda name: abs(SCALE[name] - scale()))


def scale() -> float:
    """The loaded profile's factor (read from its example count)."""
    return settings.default.max_examples / BASE_EXAMPLES


def examples(full: int) -> int:
    """The example count for a test that runs `full` examples in the full run."""
    return max(FLOOR, round(full * scale()))
