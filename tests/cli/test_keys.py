"""`buddybot keys`: the key catalogue, as lines and as JSON."""

from __future__ import annotations

import json

import pytest

from buddybot.contract import keys
from tests.cli.process import bb

pytestmark = pytest.mark.integration


def test_keys_lists_catalogue() -> None:
    out = bb("keys").stdout
    for topic in keys.TOPICS:
        assert topic.pattern in out


def test_json_is_one_document() -> None:
    table = json.loads(bb("keys", "--json").stdout)
    assert {row["key"] for row in table} >= {t.pattern for t in keys.TOPICS}
