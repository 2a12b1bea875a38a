"""`buddybot call`: a refusal is a failure; the reply printed, no server named."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from buddybot.cli.call import refusal
from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Process,
    retry_until,
)
from tests.cli.process import bb, one_line_error


def test_refusals_are_failures() -> None:
    assert refusal(m.TriggerReply(success=True)) is None
    assert refusal(m.PlaySoundReply(goal_id="g", accepted=True)) is None
    why = refusal(m.TriggerReply(success=False, message="nothing is playing"))
    assert why == "success: false (nothing is playing)"
    assert refusal(m.PlaySoundReply(goal_id="g", accepted=False)) == "accepted: false"


@pytest.mark.integration
def test_call_prints_reply_and_fails_without_server(
    endpoint: str, node_factory: Callable[..., Node]
) -> None:
    result = bb("call", "audio/stop", "--connect", endpoint, "--timeout", "1")
    assert result.returncode == 1 and "no reply" in result.stderr
    server = node_factory("server")
    server.serve(keys.AUDIO_STOP, lambda _req: m.TriggerReply(success=True, message="stopped"))
    result = retry_until(
        lambda: (r := bb("call", "audio/stop", "--connect", endpoint)).returncode == 0 and r,
        30, 0.5, "call to succeed")
    assert '"success":true' in result.stdout and "stopped" in result.stdout
    bad = bb("call", "audio/play_sound", '{"sound": ""}', "--connect", endpoint)
    assert bad.returncode == 2 and "sound" in bad.stderr


@pytest.mark.integration
def test_a_refused_call_prints_the_reply_and_exits_1(endpoint: str, spawn: Callable[..., Process]
                                                     ) -> None:
    spawn("audio-player", "--backend", "null")
    result = retry_until(
        lambda: (r := bb("call", "audio/pause", "--connect", endpoint, "--timeout", "5"))
        and "no reply" not in r.stderr and r, 60, 0.5, "the player answering")
    line = one_line_error(result)
    assert '"success":false' in result.stdout and "nothing is playing" in result.stdout
    assert "audio/pause refused" in line and "nothing is playing" in line
    ok = bb("call", "audio/stop", "--connect", endpoint, "--timeout", "5")
    assert ok.returncode == 0 and '"success":true' in ok.stdout, ok.stderr
