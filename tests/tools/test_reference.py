"""The reference pages of docs/reference/: generated from the code, and true.

The generated pages must equal what `buddybot reference` writes now (a
change of a key, message, enum, config key or verb without regenerating
fails here, like `schemas --check`); the hand-written page on writing your
own process is checked by running its example against a router.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot import cli
from buddybot.cli import reference as reference_verb
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools import reference
from buddybot.tools.testing import Collector, Process, retry_until
from tests.cli.process import bb, bb_on

ROOT = Path(__file__).resolve().parents[2]
PAGES = ROOT / "docs" / "reference"


@pytest.fixture(scope="module")
def generated() -> dict[str, str]:
    return reference.generate(cli.build_parser(), reference_verb.extensions())


def test_the_committed_pages_are_what_the_code_says(generated: dict[str, str]) -> None:
    stale = reference.drift(PAGES, generated)
    assert not stale, f"out of date: {stale}; run `.venv/bin/python -m buddybot reference`"


def test_a_stale_or_missing_page_is_found(generated: dict[str, str], tmp_path: Path) -> None:
    reference.write(tmp_path, generated)
    assert reference.drift(tmp_path, generated) == []
    (tmp_path / "enums.md").write_text(generated["enums.md"].replace("EYE_GRIN", "EYE_GRINS"))
    (tmp_path / "cli.md").unlink()
    (tmp_path / "processes.md").write_text("hand-written: not the generator's business\n")
    assert reference.drift(tmp_path, generated) == ["cli.md", "enums.md"]


def test_enums_have_their_names_and_numbers(generated: dict[str, str]) -> None:
    page = generated["enums.md"]
    for member in m.ExpressionAction:
        assert f"| {member.value} | `{member.name}` |" in page


def test_every_key_message_and_verb_has_its_entry(generated: dict[str, str]) -> None:
    for row in keys.key_table():
        assert f"| `{row['key']}` |" in generated["keys.md"]
    for cls in m.ALL_MESSAGES:
        assert f"\n## {cls.__name__}\n" in generated["messages.md"]
    for verb in (*cli.VERBS, "run camera", "radar"):
        assert f"\n## buddybot {verb}\n" in generated["cli.md"]


def test_config_keys_say_type_default_range_and_live(generated: dict[str, str]) -> None:
    page = generated["config.md"]
    assert "## [audio_player]" in page and "## [robot]" in page
    volume = next(line for line in page.splitlines() if line.startswith("| `volume` |"))
    assert volume.split(" | ")[1:5] == ["`float`", "`1.0`", "0..2", "live"]
    sample_rate = next(line for line in page.splitlines() if line.startswith("| `sample_rate`"))
    assert "restart" in sample_rate and "48000" in sample_rate


def test_attribute_docstrings_describe_fields() -> None:
    from buddybot.audio.settings import AudioPlayerSettings

    docs = reference.attribute_docs(AudioPlayerSettings)
    assert docs["sound_dirs"].startswith("Folders `audio/play_file` may play files from")


def test_every_page_links_to_a_page_that_exists(generated: dict[str, str]) -> None:
    for name, text in generated.items():
        for target in re.findall(r"\]\(([\w.]+\.md)", text):
            assert target in generated or (PAGES / target).is_file(), (name, target)


def example_program() -> str:
    text = (PAGES / "processes.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1
    return blocks[0]


@pytest.mark.integration
def test_the_process_example_runs_as_the_page_says(
        endpoint: str, node_factory: Callable[..., Node], tmp_path: Path) -> None:
    program = tmp_path / "my_listener.py"
    program.write_text(example_program())
    probe = node_factory("probe")
    seen: Collector[m.ScreenExpression] = Collector(probe, keys.EXPRESSION)
    listener = Process([sys.executable, str(program), endpoint], "my-listener", tmp_path)
    try:
        listener.wait_for_output("listening", 30)
        retry_until(lambda: "my-listener" in bb_on(endpoint, "nodes").stdout, 30, 0.3,
                    "my-listener in `buddybot nodes`")
        probe.publisher(keys.EXPRESSION).put(
            m.ScreenExpression(stamp_ns=0, action=m.ExpressionAction.EYE_SAD))
        listener.wait_for_output("eyes/expression: EYE_SAD", 30)  # callback(msg, key)
        seen.wait_for(lambda x: x.action == m.ExpressionAction.EYE_GRIN, 30, "its EYE_GRIN")
        info = retry_until(lambda: (r := bb_on(endpoint, "node", "info", "my-listener"))
                           and r.returncode == 0 and r, 30, 0.3, "node info")
        assert "eyes/expression" in info.stdout
    finally:
        listener.stop()
    assert listener.output().count("Traceback") == 0, listener.output()
    retry_until(lambda: "my-listener" not in bb("nodes", "--connect", endpoint).stdout,
                30, 0.3, "my-listener gone from `buddybot nodes`")
