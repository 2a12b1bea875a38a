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

from functools import lru_cache

STAR = "*"
DOUBLE_STAR = "**"
CHUNK_STAR = "$*"
VERBATIM = "@"
_FORBIDDEN = frozenset("#?")


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
    comes from a person: an invalid expression gets an answer, not an error."""
    return _chunks_meet(tuple(a.split("/")), tuple(b.split("/")))


@lru_cache(maxsize=4096)
def _chunks_meet(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    if not a or not b:
        return all(chunk == DOUBLE_STAR for chunk in a or b)
    if a[0] == DOUBLE_STAR:
        return _chunks_meet(a[1:], b) or (_wild_may_take(b[0]) and _chunks_meet(a, b[1:]))
    if b[0] == DOUBLE_STAR:
        return _chunks_meet(a, b[1:]) or (_wild_may_take(a[0]) and _chunks_meet(a[1:], b))
    return chunk_intersects(a[0], b[0]) and _chunks_meet(a[1:], b[1:])


def _wild_may_take(chunk: str) -> bool:
    """`*` and `**` stand for any chunk but a verbatim one."""
    return not chunk.startswith(VERBATIM)


def chunk_intersects(a: str, b: str) -> bool:
    """Whether two single chunks (no `/`) share a concrete chunk."""
    if a.startswith(VERBATIM) or b.startswith(VERBATIM):
        return a == b
    if a in (STAR, DOUBLE_STAR) or b in (STAR, DOUBLE_STAR):
        return True
    return _globs_meet(_glob(a), _glob(b))


def _glob(chunk: str) -> tuple[str | None, ...]:
    """A chunk as characters with None for each `$*`."""
    out: list[str | None] = []
    for i, part in enumerate(chunk.split(CHUNK_STAR)):
        if i:
            out.append(None)
        out.extend(part)
    return tuple(out)


@lru_cache(maxsize=4096)
def _globs_meet(a: tuple[str | None, ...], b: tuple[str | None, ...]) -> bool:
    """Whether two patterns (None: any run of characters) share a string."""
    if not a or not b:
        return all(c is None for c in a or b)
    if a[0] is None:
        return _globs_meet(a[1:], b) or _globs_meet(a, b[1:])
    if b[0] is None:
        return _globs_meet(a, b[1:]) or _globs_meet(a[1:], b)
    return a[0] == b[0] and _globs_meet(a[1:], b[1:])
