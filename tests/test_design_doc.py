"""docs/design.md lists what the code defines, so the contract page cannot drift.

The page is written by hand (it explains), but every table that can be
derived from the code is checked against it here, both ways where that
makes sense: every key of `keys.TOPICS`/`keys.SERVICES` with its message
type, codec, QoS preset and latching; every message of
`messages.ALL_MESSAGES` with every field; every service of the registry
with its config table and every key of that table; and every verb the page
names exists in the real parser. A failure says which row to add or fix.
"""

from __future__ import annotations

import re
from pathlib import Path

import msgspec
import pytest

from buddybot import cli
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime import config, errors, params, registry

DESIGN = Path(__file__).resolve().parents[1] / "docs" / "design.md"
QOS_NAMES = {id(keys.STREAM): "STREAM", id(keys.IMAGES): "IMAGES",
             id(keys.STATE): "STATE", id(keys.BACKGROUND): "BACKGROUND"}


def _text() -> str:
    return DESIGN.read_text(encoding="utf-8")


def section(number: str) -> str:
    """The text of `## <number>. ...` up to the next `## ` heading."""
    found = re.search(rf"^## {re.escape(number)}\. .*?(?=^## |\Z)", _text(), re.M | re.S)
    assert found, f"docs/design.md has no section '## {number}. ...'"
    return found.group(0)


def subsection(text: str, heading: str, level: str = "###") -> str:
    """The text under the heading line starting with `<level> <heading>`."""
    found = re.search(rf"^{level} {re.escape(heading)}.*?(?=^#{{1,{len(level)}}} |\Z)",
                      text, re.M | re.S)
    assert found, f"docs/design.md has no heading '{level} {heading}'"
    return found.group(0)


def rows(text: str) -> dict[str, list[str]]:
    """Table rows keyed by their first cell's code span (`| `x` | ... |`)."""
    out: dict[str, list[str]] = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        first = re.fullmatch(r"`([^`]+)`", cells[0]) if line.startswith("|") else None
        if first:
            out[first.group(1)] = cells
    return out


def test_the_page_exists_and_has_every_section() -> None:
    for number in ("1", "2", "3", "4", "5", "6", "7", "8"):
        assert section(number)


def test_every_topic_is_listed_with_its_type_codec_qos_and_latching() -> None:
    table = rows(subsection(section("2"), "Topics"))
    for topic in keys.TOPICS:
        assert topic.pattern in table, (
            f"docs/design.md section 2 'Topics' has no row for `{topic.pattern}`")
        _key, message, codec, qos, latched, *_ = table[topic.pattern]
        where = f"docs/design.md row `{topic.pattern}`"
        assert message == f"`{topic.type.__name__}`", f"{where}: message is {topic.type.__name__}"
        assert codec == topic.codec.name, f"{where}: codec is {topic.codec.name}"
        assert qos == f"`{QOS_NAMES[id(topic.qos)]}`", f"{where}: QoS is {QOS_NAMES[id(topic.qos)]}"
        expected = f"yes ({topic.history})" if topic.latched else "no"
        assert latched == expected, f"{where}: latched column should be {expected!r}"


def test_every_service_is_listed_with_its_request_and_reply() -> None:
    table = rows(subsection(section("2"), "Services"))
    for service in keys.SERVICES:
        assert service.pattern in table, (
            f"docs/design.md section 2 'Services' has no row for `{service.pattern}`")
        expected = f"`{service.request.__name__}` -> `{service.reply.__name__}`"
        assert table[service.pattern][1] == expected, (
            f"docs/design.md row `{service.pattern}`: should say {expected}")


def test_liveliness_key_is_listed() -> None:
    assert keys.NODES.pattern in rows(subsection(section("2"), "Liveliness"))


def test_no_key_row_names_a_key_the_catalogue_lacks() -> None:
    known = {e.pattern for e in (*keys.TOPICS, *keys.SERVICES)} | {keys.NODES.pattern}
    for heading in ("Topics", "Services", "Liveliness"):
        for key in rows(subsection(section("2"), heading)):
            assert key in known, f"docs/design.md section 2 lists `{key}`, not in keys.py"


def test_every_message_is_listed_with_every_field() -> None:
    text = section("3")
    for message in m.ALL_MESSAGES:
        block = subsection(text, f"`{message.__name__}`")
        fields = set(rows(block))
        expected = set(message.__struct_fields__)
        assert fields == expected, (
            f"docs/design.md section 3 `{message.__name__}`: missing {sorted(expected - fields)}, "
            f"not in the code {sorted(fields - expected)}")


def test_no_message_heading_names_a_message_the_code_lacks() -> None:
    names = {t.__name__ for t in m.ALL_MESSAGES}
    listed = set(re.findall(r"^### `(\w+)`", section("3"), re.M))
    assert listed <= names, f"docs/design.md section 3 lists {sorted(listed - names)}"
    assert listed == names


def test_every_service_has_its_process_row_and_config_table() -> None:
    text = section("1").split("### Configuration tables")[0]
    processes = rows(text)
    for entry in registry.SERVICES:
        assert entry.name in processes, f"docs/design.md section 1 has no row for `{entry.name}`"
        row = " | ".join(processes[entry.name])
        where = f"docs/design.md section 1, row `{entry.name}`"
        assert f"`{entry.module}`" in row, f"{where}: the module is {entry.module}"
        assert f"`[{entry.table}]`" in row, f"{where}: the config table is [{entry.table}]"


def _struct_fields(struct: type[msgspec.Struct]) -> list[msgspec.structs.FieldInfo]:
    return list(msgspec.structs.fields(struct))


def _tables() -> list[tuple[str, type[msgspec.Struct]]]:
    """Every config table: [robot], [zenoh], [apps], each service's, and nested tables."""
    found: list[tuple[str, type[msgspec.Struct]]] = [
        ("robot", config.RobotSettings), ("zenoh", config.ZenohSettings),
        ("apps", config.AppsSettings)]
    for entry in registry.SERVICES:
        assert entry.table is not None
        found.append((entry.table, entry.settings_type()))
    nested = []
    for name, struct in found:
        for field in _struct_fields(struct):
            default = (field.default_factory() if field.default_factory is not msgspec.NODEFAULT
                       else field.default)
            if isinstance(default, msgspec.Struct):
                nested.append((f"{name}.{field.name}", type(default)))
    return found + nested


@pytest.mark.parametrize("table, struct", _tables(), ids=[t for t, _ in _tables()])
def test_every_config_key_is_listed(table: str, struct: type[msgspec.Struct]) -> None:
    block = subsection(section("1"), f"`[{table}]`", level="####")
    listed = set(rows(block))
    expected = {f.name for f in _struct_fields(struct)}
    assert listed == expected, (
        f"docs/design.md section 1 `[{table}]`: missing {sorted(expected - listed)}, "
        f"not in the code {sorted(listed - expected)}")


LIVE_MARK = re.compile(r";\s*live\s*$")
"""How a row says its field is live: its meaning ends in `; live`."""


@pytest.mark.parametrize("table, struct", _tables(), ids=[t for t, _ in _tables()])
def test_the_config_tables_say_which_keys_are_live(table: str,
                                                   struct: type[msgspec.Struct]) -> None:
    """`buddybot param set` applies a live key at once and refuses the others:
    the contract says which is which (the settings struct's mark decides)."""
    block = rows(subsection(section("1"), f"`[{table}]`", level="####"))
    wrong = {name: params.is_live(struct, name) for name, cells in block.items()
             if name in struct.__struct_fields__
             and bool(LIVE_MARK.search(cells[-1])) != params.is_live(struct, name)}
    assert not wrong, (
        f"docs/design.md section 1 `[{table}]`: end the meaning with '; live' exactly for "
        f"the live keys; wrong rows (key: is live) {wrong}")


def test_every_verb_the_page_names_exists() -> None:
    parser = cli.build_parser()
    subparsers = next(a for a in parser._actions if a.dest == "verb")
    verbs = set(subparsers.choices)  # type: ignore[arg-type]
    named = set(re.findall(r"^\| `buddybot (\w[\w-]*)", section("5"), re.M))
    assert named, "docs/design.md section 5 has no verb table"
    assert named <= verbs, (
        f"docs/design.md section 5 names verbs that do not exist: {named - verbs}")


def test_exit_statuses_are_the_code_s() -> None:
    text = section("5")
    for status in (errors.EXIT_OK, errors.EXIT_FAILURE, errors.EXIT_USAGE):
        assert re.search(rf"^\| {status} \| ", text, re.M), f"exit status {status} not listed"


def test_qos_presets_are_the_code_s() -> None:
    table = rows(section("2"))
    for name in ("STREAM", "IMAGES", "STATE", "BACKGROUND"):
        qos: keys.QoS = getattr(keys, name)
        _name, congestion, priority, express, *_ = table[name]
        assert (congestion, priority, express) == (
            qos.congestion, qos.priority, "yes" if qos.express else "no"), (
            f"docs/design.md section 2, preset `{name}`: the code says {qos}")


def test_lid_table_is_the_driver_s() -> None:
    from buddybot.eyes.driver import DEFAULT_LIDS

    text = subsection(section("4"), "4.5")
    for action, pair in DEFAULT_LIDS.items():
        assert pair.left == pair.right, "the page documents symmetric defaults only"
        row = f"| {action.name} ({action.value}) | {pair.left.top:g} / {pair.left.bottom:g} |"
        assert row in text, f"docs/design.md section 4.5 lids: expected the row {row!r}"


def test_pupil_curve_default_is_the_settings_one() -> None:
    from buddybot.eyes.settings import EyesSettings

    points = ", ".join(f"({d:g}, {p:g})" for d, p in EyesSettings().pupil_curve)
    text = " ".join(subsection(section("4"), "4.5").split())
    assert f"Default points (cm, %): {points}" in text, (
        f"docs/design.md section 4.5: the default pupil curve is {points}")


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def test_links_into_the_page_point_at_its_headings() -> None:
    anchors = {_slug(h) for h in re.findall(r"^#+ (.*)$", _text(), re.M)}
    root = DESIGN.parents[1]
    pages = [root / "README.md", *sorted((root / "docs").glob("*.md"))]
    broken = [f"{page.relative_to(root)}: #{anchor}" for page in pages
              for anchor in re.findall(r"design\.md#([\w-]+)", page.read_text(encoding="utf-8"))
              if anchor not in anchors]
    broken += [f"docs/design.md: #{a}" for a in re.findall(r"\]\(#([\w-]+)\)", _text())
               if a not in anchors]
    assert not broken, f"links to missing headings of docs/design.md: {broken}"
