"""How deep untrusted JSON, JSON5 or TOML nests, measured before a recursive decoder sees it.

Python's TOML reader (behind `msgspec.toml`) and msgspec's JSON decoder
descend one call per `[` or `{`, so a file of 5,000 nested arrays ends in
a RecursionError traceback instead of an error naming the file. No file
BuddyBot reads needs more than a few levels, so text nested deeper than
MAX_DEPTH is refused up front with one line. One linear scan, no recursion:
strings (and TOML comments) are skipped so brackets inside them do not count.
"""

from __future__ import annotations

import re

MAX_DEPTH = 32
"""Deepest nesting of arrays and objects/tables a config, parameter or style
file may use (the deepest real one, a style's poses, has four)."""

_JSON_TOKENS = re.compile(rb'"(?:\\.|[^"\\])*"|[\[\]{}]', re.DOTALL)
_TOML_TOKENS = re.compile(
    rb'"""(?:\\.|[^\\])*?"""|\'\'\'.*?\'\'\'|"(?:\\.|[^"\\\n])*"|\'[^\'\n]*\'|#[^\n]*|[\[\]{}]',
    re.DOTALL)
_JSON5_TOKENS = re.compile(
    rb'"(?:\\.|[^"\\])*"|\'(?:\\.|[^\'\\])*\'|//[^\n]*|/\*.*?\*/|[\[\]{}]', re.DOTALL)
_OPEN = frozenset(b"[{")
_CLOSE = frozenset(b"]}")


class TooDeep(ValueError):
    """Text nested deeper than the limit; the text says where."""


def check_depth(text: bytes | str, *, toml: bool = False, json5: bool = False,
                limit: int = MAX_DEPTH) -> None:
    """TooDeep when `text` (JSON, TOML with `toml`, JSON5 with `json5`: comments
    and single-quoted strings skipped) nests arrays and objects deeper than
    `limit`, naming the line it happens on."""
    data = text.encode() if isinstance(text, str) else text
    if data.count(b"[") + data.count(b"{") <= limit:
        return  # the common case, at C speed: too few brackets to nest that deep
    depth = 0
    tokens = _TOML_TOKENS if toml else _JSON5_TOKENS if json5 else _JSON_TOKENS
    for token in tokens.finditer(data):
        first = token.group()[0]
        if first in _OPEN and len(token.group()) == 1:
            depth += 1
            if depth > limit:
                line = data.count(b"\n", 0, token.start()) + 1
                raise TooDeep(f"nested deeper than {limit} levels (line {line})")
        elif first in _CLOSE and len(token.group()) == 1:
            depth = max(0, depth - 1)
