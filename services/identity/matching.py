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

    A name may own several rows. Non-finite scores count as no match. For
    many probes against one gallery, build the `Index` once instead.
    """
    return Index.build(names, vectors).match(probe, threshold, margin)


@dataclass(frozen=True)
class Index:
    """A gallery's rows grouped by person, matched with a few NumPy calls.

    One single-threaded product gives every row's score, `np.maximum.reduceat` each
    person's best over their rows, and one `argmax` and one `max` the best
    person and the runner-up: 10,000 people of 16 rows match in a few
    milliseconds (benchmarks/identity_service.py), where a Python loop over
    the scores took 14.5 ms for 10,000 people of one row.
    """

    people: tuple[str, ...]
    """Each person once, in the order of their first row."""
    rows: npt.NDArray[np.float32]
    """(N, D), the rows of one person next to each other."""
    starts: npt.NDArray[np.intp]
    """Index in `rows` of each person's first row."""

    @staticmethod
    def build(names: list[str], vectors: npt.ArrayLike) -> Index:
        """Group `vectors` (N, D), row i of `names[i]`, by person."""
        order: dict[str, int] = {}
        codes = np.fromiter((order.setdefault(n, len(order)) for n in names), np.intp,
                            count=len(names))
        flat = np.asarray(vectors, dtype=np.float32)
        rows = flat.reshape(len(names), -1) if names else np.zeros((0, 0), np.float32)
        sort = np.argsort(codes, kind="stable")
        starts = np.searchsorted(codes[sort], np.arange(len(order)))
        return Index(tuple(order), np.ascontiguousarray(rows[sort]), starts)

    def match(self, probe: npt.ArrayLike, threshold: float = THRESHOLD,
              margin: float = MARGIN) -> Match:
        """The answer for one unit `probe` (D,)."""
        p = np.asarray(probe, dtype=np.float32).ravel()
        if not self.people:
            return Match(None, None, float("nan"), float("nan"), "gallery is empty")
        if self.rows.shape[1] != p.shape[0]:
            raise ValueError(f"probe has {p.shape[0]} numbers, gallery rows {self.rows.shape[1]}")
        # einsum, not `@`: BLAS's matrix-vector product spreads over every core and, on a
        # busy robot, waits for them (25 ms instead of 8 for 160,000 rows here).
        scores = np.nan_to_num(np.einsum("ij,j->i", self.rows, p), nan=-1.0, posinf=-1.0,
                               neginf=-1.0)
        per_person = np.maximum.reduceat(scores, self.starts)
        top = int(np.argmax(per_person))
        best, score = self.people[top], float(per_person[top])
        per_person[top] = -np.inf
        runner_up = float(per_person.max()) if len(per_person) > 1 else -1.0
        if score < threshold:
            return Match(None, best, score, runner_up,
                         f"best score {score:.3f} is below the threshold {threshold:.3f}")
        if score - runner_up < margin:
            return Match(None, best, score, runner_up,
                         f"best score {score:.3f} is within {margin:.3f} of the runner-up "
                         f"{runner_up:.3f}")
        return Match(best, best, score, runner_up, "clear match")
