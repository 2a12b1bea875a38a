"""Key-expression validity and intersection, against a table and against Zenoh itself."""

from __future__ import annotations

import pytest
import zenoh
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from buddybot.contract import keyexpr
from tests.properties import examples


@pytest.mark.parametrize(("a", "b", "hit"), [
    ("radar/0/frames", "radar/*/frames", True),
    ("radar/0/frames", "radar/**", True),
    ("radar/0/frames", "**", True),
    ("radar/0/frames", "radar/1/frames", False),
    ("camera/front/face", "camera/*/image", False),
    ("a/b/c", "a/**/c", True),
    ("a/c", "a/**/c", True),
    ("a", "a/**", True),
    ("a/b", "a/b/c", False),
    ("a/b", "a/*/*", False),
    ("camera/front/faces", "camera/fr$*/faces", True),
    ("camera/front/faces", "camera/$*nt/faces", True),
    ("camera/front/faces", "camera/b$*/faces", False),
    ("a$*b", "ab", True),
    ("a$*", "$*b", True),
    ("a$*b", "c$*", False),
    ("x/@a/y", "x/**", False),
    ("x/@a/y", "x/*/y", False),
    ("x/@a/y", "**/@a/y", True),
    ("@a$*", "@ab", False),
    ("@a", "a", False),
])
def test_intersection(a: str, b: str, hit: bool) -> None:
    assert keyexpr.intersects(a, b) is hit
    assert keyexpr.intersects(b, a) is hit


@pytest.mark.parametrize(("expr", "ok"), [
    ("buddybot/buddy/radar/0/frames", True),
    ("buddybot/*/camera/**", True),
    ("**/*", True),
    ("a/cam$*", True),
    ("$*", True),
    ("@a/b", True),
    ("", False),
    ("/a", False),
    ("a/", False),
    ("a//b", False),
    ("cam*", False),
    ("***", False),
    ("a$", False),
    ("a$$*", False),
    ("$**", False),
    ("a#b", False),
    ("a?b", False),
])
def test_validity(expr: str, ok: bool) -> None:
    assert keyexpr.valid(expr) is ok


CHUNKS = st.one_of(
    st.sampled_from(["*", "**", "a", "b", "ab", "@a", "@b"]),
    st.lists(st.sampled_from(["a", "b", "$*"]), min_size=1, max_size=4).map("".join),
)
EXPRESSIONS = st.lists(CHUNKS, min_size=1, max_size=5).map("/".join)


def zenoh_key(text: str) -> zenoh.KeyExpr:
    """Zenoh's own parse; only canonical expressions are compared (Zenoh's
    canonizer is not the question here, and it panics on `a$*$*`)."""
    assume("$*$*" not in text and keyexpr.valid(text))
    try:
        return zenoh.KeyExpr(text)
    except zenoh.ZError:
        assume(False)
        raise


@settings(max_examples=examples(400))
@given(EXPRESSIONS, EXPRESSIONS)
def test_intersection_agrees_with_zenoh(a: str, b: str) -> None:
    assert keyexpr.intersects(a, b) is zenoh_key(a).intersects(zenoh_key(b))


@settings(max_examples=examples(800))
@given(st.text(alphabet="ab*$/@#", max_size=8))
def test_validity_agrees_with_zenoh(text: str) -> None:
    assume("$*$*" not in text)  # Zenoh's canonizer panics on some of these
    try:
        zenoh.KeyExpr.autocanonize(text)
        accepted = True
    except zenoh.ZError:
        accepted = False
    assert keyexpr.valid(text) is accepted


def test_long_untrusted_keys_neither_recurse_nor_match() -> None:
    """A recording's channel name can be anything: thousands of chunks or `$*`s end
    in an answer, never a RecursionError, and past MAX_CHARS nothing matches."""
    deep = "/".join(["a"] * 900)  # 1799 characters, 900 chunks
    assert not keyexpr.intersects("**", deep)
    near = "/".join(["a"] * 500)  # 999 characters: within the bound, matched
    assert keyexpr.intersects("**/a", near) and keyexpr.intersects(near, "a/**")
    globs = "$*a" * 300  # one chunk of 900 characters with 300 wildcards
    assert keyexpr.intersects(globs, "a" * 300)
    assert not keyexpr.intersects(globs, "b" * 300)
