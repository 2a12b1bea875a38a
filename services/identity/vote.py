"""The vote of one face track: a name only when several of its frames agree on it.

One embedding says little (a blurred frame, a turned head); a wrong name is
worse than none. So each track embeds one frame in `every_nth`, at most one
at a time (the frame being embedded is a value, `pending`, that the result
must name to count), and is named only when `needed` of its last `window`
answers accepted the same name and none accepted another. Disagreement or
no accept keeps it unknown. Once named, the track is only re-checked every
`recheck_s` (the name falls back to unknown if the re-checks stop agreeing),
and a forgotten name is struck from its answers at once.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field


@dataclass(frozen=True)
class VoteRules:
    every_nth: int = 3
    needed: int = 3
    window: int = 5
    recheck_s: float = 5.0

    def __post_init__(self) -> None:
        if self.every_nth < 1 or not 1 <= self.needed <= self.window or self.recheck_s <= 0:
            raise ValueError("need every_nth >= 1, 1 <= needed <= window, recheck_s > 0")


@dataclass(frozen=True)
class Answer:
    """One embedded frame's match: `name` None when it accepted nobody."""

    stamp_ns: int
    name: str | None
    score: float


@dataclass
class TrackVote:
    """The vote of track `track`; `frame` says when to embed, `answer` takes the result."""

    track: int
    rules: VoteRules
    answers: deque[Answer] = field(default_factory=deque)
    pending: int | None = None
    """Stamp of the frame being embedded now (None: nothing in flight)."""
    since_embed: int | None = None
    """Frames since the last embedding started (None: none started yet)."""
    name: str | None = None
    score: float | None = None
    votes: int = 0
    recheck_ns: int = 0

    def frame(self, stamp_ns: int) -> bool:
        """One frame of this track with its face; True: embed this one (now pending)."""
        if self.since_embed is not None:
            self.since_embed += 1
        if self.pending is not None:
            return False
        if self.name is not None:
            if stamp_ns < self.recheck_ns:
                return False
        elif self.since_embed is not None and self.since_embed < self.rules.every_nth:
            return False
        self.pending, self.since_embed = stamp_ns, 0
        return True

    def answer(self, got: Answer) -> bool:
        """The result of the pending embedding; True when the name changed.

        A result for another frame than the pending one (a stale job) is ignored.
        """
        if got.stamp_ns != self.pending:
            return False
        self.pending = None
        self.answers.append(got)
        while len(self.answers) > self.rules.window:
            self.answers.popleft()
        return self._decide(got.stamp_ns)

    def failed(self, stamp_ns: int) -> None:
        """The pending embedding gave nothing (no image, bad keypoints): try a later frame."""
        if stamp_ns == self.pending:
            self.pending = None

    def forget(self, names: set[str] | None) -> bool:
        """Strike forgotten names (None: everybody) from the answers; True if the name changed."""
        kept = [a if names is not None and a.name not in names else
                Answer(a.stamp_ns, None, a.score) for a in self.answers]
        self.answers = deque(kept)
        before = self.name
        self._decide(self.answers[-1].stamp_ns if self.answers else 0)
        return self.name != before

    def _decide(self, stamp_ns: int) -> bool:
        accepted = [a for a in self.answers if a.name is not None]
        names = {a.name for a in accepted}
        before = self.name
        if len(names) == 1 and len(accepted) >= self.rules.needed:
            self.name = accepted[-1].name
            self.score = accepted[-1].score
            self.votes = len(accepted)
            self.recheck_ns = stamp_ns + int(self.rules.recheck_s * 1e9)
        else:
            self.name, self.score = None, None
            self.votes = len(self.answers)
        return self.name != before
