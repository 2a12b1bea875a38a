"""The example of docs/sdk.md, run as it is shown (marked `integration`): a program
connected with the standard flags, a real people service and real audio services, a
visitor arriving -> "Hello there" (configured nowhere) is spoken to its end."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import Collector, Process, retry_until
from tests.people.test_service import Visitor

DOC = Path(__file__).resolve().parents[2] / "docs" / "sdk.md"


def example_code() -> str:
    """The first ```python block of docs/sdk.md."""
    lines = DOC.read_text().splitlines()
    start = lines.index("```python") + 1
    return "\n".join(lines[start:lines.index("```", start)]) + "\n"


def test_the_page_has_an_example_using_the_standard_flags() -> None:
    code = example_code()
    compile(code, str(DOC), "exec")
    assert "sdk.add_arguments(parser)" in code and "Bot.from_args(args)" in code


@pytest.mark.integration
def test_the_example_greets_a_visitor(spawn: Callable[..., Process], probe: Node,
                                      endpoint: str, log_dir: Path, tmp_path: Path) -> None:
    config = tmp_path / "robot.toml"
    config.write_text("[audio_player]\nbackend = \"null\"\n")
    state = Collector[m.PeopleState](probe, keys.PEOPLE_STATE)
    free = Collector[m.Bool](probe, keys.DEVICE_FREE)
    status = Collector[m.PlaySoundStatus](probe, keys.PLAY_SOUND_STATUS)
    spawn("people", "--config", str(config))
    spawn("audio", "--config", str(config))
    spawn("audio-player", "--config", str(config))
    state.wait_for(lambda s: s.people == [], 30, "the people service up")
    free.wait_for(lambda b: b.data, 30, "the player up")
    retry_until(lambda: any(i.node == "audio" and "audio/play_sound" in i.services
                            for i in probe.node_infos(1.0)),
                30, 0.2, "the audio action server answering")
    script = tmp_path / "greeter.py"
    script.write_text(example_code())
    program = Process([sys.executable, str(script), "--connect", endpoint, "--config",
                       str(config)], "greeter", log_dir)
    try:
        program.wait_for_output("watching; present now: []", 30)
        Visitor(probe).presence(True, 1.0)
        status.wait_for(lambda s: s.state == "SUCCEEDED", 60, "the greeting spoken")
        assert program.alive() and "not spoken" not in program.output()
    finally:
        program.stop()
