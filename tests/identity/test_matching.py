"""The accept rule (pure), then on real photos: same person -> their name, others -> never it."""

from __future__ import annotations

import numpy as np
import pytest

from buddybot.identity import matching
from buddybot.identity.embedding import unit
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
