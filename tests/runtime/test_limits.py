"""Input limits, without processes: stamp window, clipped text, bounded tables."""

from __future__ import annotations

import pytest

from buddybot.runtime import limits

S = 1_000_000_000


def test_stamp_window_bounds() -> None:
    now = 1_800_000_000 * S
    assert limits.stamp_plausible(now, now)
    assert limits.stamp_plausible(now - 10 * S, now)
    assert not limits.stamp_plausible(now - 10 * S - 1, now)
    assert limits.stamp_plausible(now + 1 * S, now)
    assert not limits.stamp_plausible(now + 1 * S + 1, now)
    assert not limits.stamp_plausible(2**63 - 1, now)
    assert not limits.stamp_plausible(0, now)
    assert limits.stamp_plausible(now - 30 * S, now, past_s=60)


def test_implausible_stamp_is_replaced_by_arrival() -> None:
    now = 1_800_000_000 * S
    assert limits.plausible_stamp(now - S, now) == (now - S, False)
    assert limits.plausible_stamp(now + 15 * S, now) == (now, True)
    assert limits.plausible_stamp(2**63 - 1, now) == (now, True)


def test_clip_keeps_short_text_and_says_how_much_was_cut() -> None:
    assert limits.clip("hello") == "hello"
    clipped = limits.clip("x" * 10_000_000)
    assert len(clipped) < 260 and clipped.endswith("(+9999800 chars)")
    assert limits.clip(b"\x00" * 5, limit=4).startswith("b'\\x")


def test_bounded_dict_evicts_least_recently_touched() -> None:
    table: limits.BoundedDict[str, int] = limits.BoundedDict(3)
    for name in "abc":
        table[name] = ord(name)
    table["a"] = 1  # refreshed: now the newest
    table["d"] = 4
    assert set(table) == {"a", "c", "d"}
    assert table.evicted == 1 and len(table) == 3
    table.touch("c")
    table["e"] = 5
    assert "a" not in table and "c" in table and table.evicted == 2
    assert table.get("zz") is None and table.pop("c") == ord("c") and len(table) == 2
    for i in range(10_000):
        table[f"fake{i}"] = i
    assert len(table) == 3 and table.evicted == 2 + 10_000 - 1


def test_bounded_dict_needs_room() -> None:
    with pytest.raises(ValueError):
        limits.BoundedDict(0)
