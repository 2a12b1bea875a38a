"""schemas/ is generated from the types; it must not drift."""

from __future__ import annotations

import json
from pathlib import Path

from buddybot.core import keys, schemas
from buddybot.core import messages as m

ROOT = Path(__file__).resolve().parents[2]


def test_committed_schemas_match_the_types() -> None:
    stale = schemas.drift(ROOT / "schemas")
    assert stale == [], f"run `buddybot schemas` to regenerate: {stale}"


def test_drift_is_detected(tmp_path: Path) -> None:
    schemas.write(tmp_path)
    assert schemas.drift(tmp_path) == []
    target = tmp_path / "messages" / "PupilControl.json"
    target.write_text(target.read_text().replace("dilation_percentage", "dilation"))
    (tmp_path / "messages" / "Old.json").write_text("{}")
    assert schemas.drift(tmp_path) == ["messages/Old.json", "messages/PupilControl.json"]


def test_key_table_lists_every_key() -> None:
    table = json.loads(schemas.generate()["keys.json"])
    assert {row["key"] for row in table} >= {t.pattern for t in keys.TOPICS}
    assert len(schemas.generate()) == len(m.ALL_MESSAGES) + 1
