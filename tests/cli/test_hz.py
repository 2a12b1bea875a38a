"""`buddybot hz` as a process: the rate of a key, as lines and as JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from buddybot.tools.testing import (
    Process,
    buddybot_argv,
)
from tests.cli.process import bb

pytestmark = pytest.mark.integration


def test_pub_rate_and_hz(endpoint: str, log_dir: Path) -> None:
    talker = Process(buddybot_argv("pub", "eyes/pupil", '{"dilation_percentage": 5}',
                                   "--rate", "20", "--connect", endpoint), "talker", log_dir)
    try:
        result = bb("hz", "eyes/pupil", "--connect", endpoint, "--duration", "4")
        assert result.returncode == 0, result.stderr
        rates = [float(line.split()[2]) for line in result.stdout.splitlines()
                 if line.startswith("average rate")]
        assert rates and 10 < rates[-1] < 30
    finally:
        talker.stop()


def test_hz_json_reports_the_rate(endpoint: str, log_dir: Path) -> None:
    talker = Process(buddybot_argv("pub", "eyes/pupil", '{"dilation_percentage": 5}',
                                   "--rate", "20", "--connect", endpoint), "talker", log_dir)
    try:
        result = bb("hz", "eyes/pupil", "--json", "--duration", "4", "--connect", endpoint)
    finally:
        talker.stop()
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["key"] == "buddybot/buddy/eyes/pupil" and 10 < report["rate_hz"] < 30
    assert report["received"] >= report["window"] >= 2
