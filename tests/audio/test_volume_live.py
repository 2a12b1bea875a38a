"""`buddybot param set audio-player volume 0.5` halves the next sound, no restart."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from buddybot.tools.testing import buddybot_argv

from .conftest import beep_config, final, send_goal

pytestmark = pytest.mark.integration


def param(endpoint: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(buddybot_argv("param", *args, "--connect", endpoint, "--timeout", "10"),
                          capture_output=True, text=True, timeout=60)


def test_volume_applies_to_the_next_sound(audio, probe, tmp_path, endpoint) -> None:
    config, samples = beep_config(tmp_path, 0.3)
    a = audio(config)
    assert a.player is not None
    pid = a.player.pid
    first = send_goal(probe, "beep")
    assert final(a, first.goal_id).state == "SUCCEEDED"

    result = param(endpoint, "set", "audio-player", "volume", "0.5")
    assert result.returncode == 0, result.stderr
    refused = param(endpoint, "set", "audio-player", "sample_rate", "44100")
    assert refused.returncode == 1 and "sample_rate needs a restart" in refused.stderr
    second = send_goal(probe, "beep")
    assert final(a, second.goal_id).state == "SUCCEEDED"
    assert a.player.pid == pid and a.player.alive()

    a.player.stop()  # the tap file is complete once the player exited
    tap = a.tap_samples().astype(np.int32)
    n = samples.shape[0]
    assert tap.shape[0] == 2 * n
    assert np.array_equal(tap[:n], samples)
    # Half the gain (rounded to int16), not the same sound again.
    assert np.abs(tap[n:] - samples.astype(np.int32) * 0.5).max() <= 1
    assert np.abs(tap[n:]).max() < np.abs(samples).max() * 0.6
