"""A track's vote: one frame in N embedded, one at a time; a name only when K of the
last M answers agree and none names someone else; re-checks; forgotten names struck."""

from __future__ import annotations

import pytest

from buddybot.identity.vote import Answer, TrackVote, VoteRules

MS = 1_000_000


def _vote(**rules: float) -> TrackVote:
    return TrackVote(1, VoteRules(**{"every_nth": 2, "needed": 2, "window": 3,
                                     "recheck_s": 1.0, **rules}))  # type: ignore[arg-type]


def _embed(v: TrackVote, stamp: int, name: str | None, score: float = 0.95) -> bool:
    assert v.frame(stamp), f"frame {stamp} should be embedded"
    return v.answer(Answer(stamp, name, score))


def test_bad_rules_are_refused() -> None:
    with pytest.raises(ValueError):
        VoteRules(needed=4, window=3)
    with pytest.raises(ValueError):
        VoteRules(every_nth=0)


def test_one_frame_in_n_and_never_two_in_flight() -> None:
    v = _vote(every_nth=3)
    assert v.frame(0) and v.pending == 0
    assert [v.frame(t) for t in (1, 2, 3, 4)] == [False] * 4  # the first still pending
    v.answer(Answer(0, None, 0.5))
    assert v.frame(5) and v.pending == 5  # 5 frames since: due at once
    v.answer(Answer(5, None, 0.5))
    assert [v.frame(t) for t in (6, 7, 8)] == [False, False, True]


def test_a_stale_answer_does_not_count() -> None:
    v = _vote()
    v.frame(10)
    assert not v.answer(Answer(9, "ada", 0.99))
    assert v.pending == 10 and not v.answers
    v.failed(10)
    assert v.pending is None


def test_k_agreeing_answers_name_the_track() -> None:
    v = _vote()
    assert not _embed(v, 0, "ada")
    v.frame(1)
    assert _embed(v, 2, "ada", 0.97)
    assert (v.name, v.score, v.votes) == ("ada", 0.97, 2)


def test_disagreement_or_no_accept_stays_unknown() -> None:
    v = _vote(needed=2, window=4)
    for i, name in enumerate(["ada", "bob", "ada", None]):
        _embed(v, 2 * i, name)
        v.frame(2 * i + 1)
    assert v.name is None  # ada twice, but bob once: never a name
    w = _vote()
    for i in range(6):
        _embed(w, 2 * i, None)
        w.frame(2 * i + 1)
    assert w.name is None and w.votes == 3


def test_a_named_track_is_only_rechecked_and_loses_its_name_on_disagreement() -> None:
    v = _vote(recheck_s=1.0)
    _embed(v, 0, "ada")
    v.frame(1)
    _embed(v, 2, "ada")
    assert v.name == "ada"
    assert not any(v.frame(t) for t in range(3 * MS, 999 * MS, 33 * MS))
    assert v.frame(1002 * MS)
    v.answer(Answer(1002 * MS, None, 0.5))  # a turned head: still ada
    assert v.name == "ada"
    v.frame(2100 * MS)
    assert v.answer(Answer(2100 * MS, "bob", 0.95))
    assert v.name is None


def test_a_forgotten_name_is_struck_at_once() -> None:
    v = _vote()
    _embed(v, 0, "ada")
    v.frame(1)
    _embed(v, 2, "ada")
    assert v.forget({"bob"}) is False and v.name == "ada"
    assert v.forget({"ada"}) is True and v.name is None
    assert all(a.name is None for a in v.answers)
    u = _vote()
    _embed(u, 0, "ada")
    u.frame(1)
    _embed(u, 2, "ada")
    assert u.forget(None) and u.name is None
