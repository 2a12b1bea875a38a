"""Zenoh key expressions, read by Zenoh's rules without Zenoh (pure).

A key expression is chunks joined by `/`: `*` is any one chunk, `**` any
number of chunks (none too), `$*` inside a chunk any run of characters
(`cam$*` is every chunk starting with `cam`), and a chunk starting with `@`
is verbatim: only the same chunk meets it, no wildcard does. Two
expressions intersect when some concrete key belongs to both; a concrete
key "matches" an expression exactly when they intersect.

`buddybot topics`, the bag reader and the probes (which keys of the
catalogue an `echo` or `hz` key can carry) all ask this one question, so
it is answered here, for strings, without a session.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

STAR = "*"
DOUBLE_STAR = "**"
CHUNK_STAR = "$*"
VERBATIM = "@"
_FORBIDDEN = frozenset("#?")
MAX_CHARS = 1024
"""Longer than any key of the catalogue by far; an expression longer than this
meets nothing (bounds the matching's time on untrusted keys)."""
T = TypeVar("T")


def valid(expr: str) -> bool:
    """Whether Zenoh accepts `expr` (possibly after putting it in canonical form):
    no empty chunk (no leading, trailing or doubled `/`), no `#` or `?`, `$` only
    in `$*`, and `*` only as a whole chunk `*` or `**` or inside `$*`."""
    if not expr or _FORBIDDEN & set(expr):
        return False
    return all(_valid_chunk(chunk) for chunk in expr.split("/"))


def _valid_chunk(chunk: str) -> bool:
    if chunk in (STAR, DOUBLE_STAR):
        return True
    rest = chunk.replace(CHUNK_STAR, "")
    return bool(chunk) and "$" not in rest and STAR not in rest


def intersects(a: str, b: str) -> bool:
    """Whether some key belongs to both expressions (a concrete key and an
    expression: whether the key matches). Check `valid` first where the text
    comes from a person: an invalid expression gets an answer, not an error.

    Keys can come from untrusted places (a recording's channel names), so the
    work is bounded: an expression longer than `MAX_CHARS` meets nothing, and
    the matching is a table filled in a loop (no recursion on the input's length)."""
    if len(a) > MAX_CHARS or len(b) > MAX_CHARS:
        return False
    return _meet(a.split("/"), b.split("/"), DOUBLE_STAR, chunk_intersects, _wild_may_take)


def _wild_may_take(chunk: str) -> bool:
    """`*` and `**` stand for any chunk but a verbatim one."""
    return not chunk.startswith(VERBATIM)


def chunk_intersects(a: str, b: str) -> bool:
    """Whether two single chunks (no `/`) share a concrete chunk."""
    if a.startswith(VERBATIM) or b.startswith(VERBATIM):
        return a == b
    if a in (STAR, DOUBLE_STAR) or b in (STAR, DOUBLE_STAR):
        return True
    return _meet(_glob(a), _glob(b), None, lambda x, y: x == y, lambda _x: True)


def _glob(chunk: str) -> list[str | None]:
    """A chunk as characters with None for each `$*`."""
    out: list[str | None] = []
    for i, part in enumerate(chunk.split(CHUNK_STAR)):
        if i:
            out.append(None)
        out.extend(part)
    return out


def _meet(a: Sequence[T], b: Sequence[T], wild: T, same: Callable[[T, T], bool],
          takes: Callable[[T], bool]) -> bool:
    """Whether two patterns share a concrete sequence. `wild` stands for any run of
    items (none too) that `takes` accepts; other items meet when `same` says so.

    `reach[j]` for the row of `i` says whether `a[i:]` and `b[j:]` can meet; rows
    are filled from the end, so time is len(a) * len(b) and memory one row."""
    n, m = len(a), len(b)
    below = [False] * (m + 1)  # the row of i + 1
    for i in range(n, -1, -1):
        row = [False] * (m + 1)
        for j in range(m, -1, -1):
            if i == n:
                row[j] = all(x == wild for x in b[j:])
            elif j == m:
                row[j] = a[i] == wild and below[j]
            elif a[i] == wild:
                row[j] = below[j] or (takes(b[j]) and row[j + 1])
            elif b[j] == wild:
                row[j] = row[j + 1] or (takes(a[i]) and below[j])
            else:
                row[j] = same(a[i], b[j]) and below[j + 1]
        below = row
    return below[0]
