"""Running `buddybot` as a user does, a process to its end, for the verb tests."""

from __future__ import annotations

import subprocess

from buddybot.tools.testing import buddybot_argv, retry_until


def bb(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """`buddybot ARGS` to its end: status, stdout and stderr."""
    return subprocess.run(buddybot_argv(*args), capture_output=True, text=True, timeout=timeout)


def bb_on(endpoint: str, *args: str, timeout: str = "10") -> subprocess.CompletedProcess[str]:
    """`buddybot ARGS --connect ENDPOINT --timeout S`: a verb that asks the robot."""
    return bb(*args, "--connect", endpoint, "--timeout", timeout)


def one_line_error(result: subprocess.CompletedProcess[str]) -> str:
    """The stderr line of a failed probe: exit 1, no traceback."""
    assert result.returncode == 1, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.startswith("buddybot ")]
    assert len(lines) == 1, result.stderr
    return lines[0]


def wait_params(endpoint: str, node: str) -> None:
    """Until the node answers (it declares its queryable after connecting)."""
    retry_until(lambda: bb_on(endpoint, "param", "list", node, timeout="1").returncode == 0,
                30, 0.2, f"{node} answering params")
