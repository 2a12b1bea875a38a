"""The accept rule (pure), then on real photos: same person -> their name, others -> never it."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.identity import matching
from buddybot.identity.embedding import unit
from buddybot.identity.matching import Index
from tests.identity.photos import Photo


def vec(*xs: float) -> np.ndarray:
    return unit(np.array(xs, dtype=np.float32))


def test_a_clear_best_match_is_named() -> None:
    answer = matching.best_match(vec(1, 0, 0), ["ada", "bob"], [vec(1, 0.1, 0), vec(0, 1, 0)])
    assert answer.name == "ada" and answer.best == "ada"
    assert answer.score > matching.THRESHOLD and answer.runner_up < 0.2


def test_below_the_threshold_stays_unknown() -> None:
    answer = matching.best_match(vec(1, 0, 0), ["ada"], [vec(1, 1, 0)])
    assert answer.name is None and answer.best == "ada" and "threshold" in answer.reason


def test_two_close_people_stay_unknown() -> None:
    answer = matching.best_match(vec(1, 0, 0), ["ada", "bob"], [vec(1, 0.01, 0), vec(1, 0, 0.02)])
    assert answer.name is None and "runner-up" in answer.reason


def test_several_rows_of_one_person_are_not_their_own_runner_up() -> None:
    answer = matching.best_match(vec(1, 0, 0), ["ada", "ada"], [vec(1, 0.01, 0), vec(1, 0, 0.01)])
    assert answer.name == "ada"


def test_empty_gallery_and_bad_rows() -> None:
    assert matching.best_match(vec(1, 0), [], np.zeros((0, 2))).name is None
    with pytest.raises(ValueError):
        matching.best_match(vec(1, 0, 0), ["ada"], [vec(1, 0)])
    nan = matching.best_match(vec(1, 0), ["ada"], [[np.nan, np.nan]])
    assert nan.name is None


def test_same_person_on_other_photos_gets_their_name(
        shots: list[Photo], vectors: dict[str, np.ndarray]) -> None:
    """Every photo whose person has another independent shot enrolled is named correctly."""
    named = 0
    for probe in shots:
        others = [p for p in shots if p.source != probe.source]
        if not any(p.person == probe.person for p in others):
            continue
        answer = matching.best_match(vectors[probe.name], [p.person for p in others],
                                     np.stack([vectors[p.name] for p in others]))
        assert answer.name == probe.person, (probe.name, answer)
        named += 1
    assert named >= 5


def test_nobody_is_ever_given_someone_elses_name(
        shots: list[Photo], vectors: dict[str, np.ndarray]) -> None:
    """0 false accepts: each photo against galleries of everybody else, with and without them."""
    for probe in shots:
        strangers = [p for p in shots if p.person != probe.person]
        answer = matching.best_match(vectors[probe.name], [p.person for p in strangers],
                                     np.stack([vectors[p.name] for p in strangers]))
        assert answer.name is None, (probe.name, answer)
        for one in strangers:  # a gallery of a single other person: no runner-up to help
            alone = matching.best_match(vectors[probe.name], [one.person], [vectors[one.name]])
            assert alone.name is None, (probe.name, one.name, alone)


def _loop_match(probe: np.ndarray, names: list[str], rows: np.ndarray, threshold: float,
                margin: float) -> tuple[str | None, str, float, float]:
    """The plain Python reference: each person's best row, then best and runner-up."""
    best_of: dict[str, float] = {}
    for name, row in zip(names, rows, strict=True):
        best_of[name] = max(float(row @ probe), best_of.get(name, -1.0))
    ranked = sorted(best_of.items(), key=lambda kv: kv[1], reverse=True)
    best, score = ranked[0]
    runner = ranked[1][1] if len(ranked) > 1 else -1.0
    accepted = best if score >= threshold and score - runner >= margin else None
    return accepted, best, score, runner


@pytest.mark.parametrize("seed", range(20))
def test_the_vectorised_match_equals_the_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    people = int(rng.integers(1, 40))
    names = [f"p{int(i)}" for i in rng.integers(0, people, size=int(rng.integers(1, 200)))]
    rows = rng.normal(size=(len(names), 16)).astype(np.float32)
    rows /= np.linalg.norm(rows, axis=1, keepdims=True)
    index = Index.build(names, rows)
    for _ in range(5):
        near = rows[int(rng.integers(0, len(names)))] + rng.normal(scale=0.05, size=16)
        probe = (near / np.linalg.norm(near)).astype(np.float32)
        threshold, margin = float(rng.uniform(0.3, 0.99)), float(rng.uniform(0.0, 0.1))
        got = index.match(probe, threshold, margin)
        want = _loop_match(probe, names, rows, threshold, margin)
        assert (got.name, got.best) == want[:2]
        assert got.score == pytest.approx(want[2], abs=1e-5)
        assert got.runner_up == pytest.approx(want[3], abs=1e-5)
