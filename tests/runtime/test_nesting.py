"""Nesting depth of untrusted JSON and TOML, measured without recursion."""

from __future__ import annotations

import pytest

from buddybot.runtime.nesting import MAX_DEPTH, TooDeep, check_depth


def test_deep_arrays_and_tables_are_refused_naming_the_line() -> None:
    check_depth(b"[" * MAX_DEPTH + b"]" * MAX_DEPTH)
    with pytest.raises(TooDeep, match=f"nested deeper than {MAX_DEPTH} levels \\(line 1\\)"):
        check_depth(b"[" * (MAX_DEPTH + 1) + b"]" * (MAX_DEPTH + 1))
    with pytest.raises(TooDeep, match="line 3"):
        check_depth("[t]\n\nx = " + "{a = " * 40 + "1" + "}" * 40, toml=True)
    with pytest.raises(TooDeep):  # a hundred thousand levels: no RecursionError here
        check_depth(b"[" * 100_000)


def test_brackets_in_strings_and_comments_do_not_count() -> None:
    many = "[" * 100
    check_depth(f'{{"a": "{many}\\"{many}", "b": ["{many}"]}}')
    toml = (f'a = "{many}"\nb = \'{many}\'\nc = """\n{many}\n"""\nd = \'\'\'{many}\'\'\'\n'
            f"# {many}\n[[e]]\nf = [[1], [2]]\n")
    check_depth(toml, toml=True)
