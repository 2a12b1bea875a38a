"""`[identity]`: off by default, the vote's rules checked, the gallery in the state directory."""

from __future__ import annotations

import msgspec
import pytest

from buddybot.identity.service import rules_of
from buddybot.identity.settings import IdentitySettings


def test_identity_is_opt_in() -> None:
    assert IdentitySettings().enabled is False


def test_more_votes_than_the_window_count_as_the_whole_window() -> None:
    rules = rules_of(msgspec.convert({"votes_needed": 6, "vote_window": 5}, IdentitySettings))
    assert (rules.needed, rules.window) == (5, 5)


def test_retention_is_positive_days_or_none() -> None:
    assert msgspec.convert({"retention_days": 30}, IdentitySettings).retention_days == 30
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert({"retention_days": 0}, IdentitySettings)
