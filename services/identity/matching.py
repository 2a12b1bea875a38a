"""One face's embedding against the gallery: a name only when the answer is clear.

A wrong name is worse than no name, so the best-matching person is named
only when their score clears `threshold` AND beats the best other person
by `margin` (two look-alikes, or a stranger halfway between two people,
stay unknown). Scores are cosine similarities of unit vectors; a person
with several enrolled embeddings scores their best one. Agreement over
several frames of one track is the identity stage's job, on top of this.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

THRESHOLD = 0.93
"""Cosine a match must reach (dlib's own rule, distance 0.6 on its near-unit
vectors, is about cosine 0.82; ours is stricter: docs/identity.md has the
figures it comes from)."""
MARGIN = 0.03
"""How far the best person must be ahead of the runner-up."""


@dataclass(frozen=True)
class Match:
    """The answer for one face: `name` is None when unknown, `reason` says why."""

    name: str | None
    best: str | None
    score: float
    runner_up: float
    reason: str


def best_match(probe: npt.ArrayLike, names: list[str], vectors: npt.ArrayLike,
               threshold: float = THRESHOLD, margin: float = MARGIN) -> Match:
    """Match a unit `probe` (D,) against `vectors` (N, D), row i enrolled for `names[i]`.

    A name may own several rows. Non-finite scores count as no match.
    """
    p = np.asarray(probe, dtype=np.float32).ravel()
    rows = np.asarray(vectors, dtype=np.float32).reshape(len(names), -1) if names else None
    if rows is None or rows.shape[0] == 0:
        return Match(None, None, float("nan"), float("nan"), "gallery is empty")
    if rows.shape[1] != p.shape[0]:
        raise ValueError(f"probe has {p.shape[0]} numbers, gallery rows {rows.shape[1]}")
    scores = np.nan_to_num(rows @ p, nan=-1.0, posinf=-1.0, neginf=-1.0)
    per_person: dict[str, float] = {}
    for name, score in zip(names, scores.tolist(), strict=True):
        per_person[name] = max(score, per_person.get(name, -1.0))
    ranked = sorted(per_person.items(), key=lambda kv: kv[1], reverse=True)
    best, score = ranked[0]
    runner_up = ranked[1][1] if len(ranked) > 1 else -1.0
    if score < threshold:
        return Match(None, best, score, runner_up,
                     f"best score {score:.3f} is below the threshold {threshold:.3f}")
    if score - runner_up < margin:
        return Match(None, best, score, runner_up,
                     f"best score {score:.3f} is within {margin:.3f} of the runner-up "
                     f"{runner_up:.3f}")
    return Match(best, best, score, runner_up, "clear match")
