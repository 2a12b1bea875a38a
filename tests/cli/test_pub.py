"""`buddybot pub` as a process: validation naming the field, a publish nobody hears."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.node import Node
from buddybot.tools.testing import (
    Collector,
    free_port,
)
from tests.cli.process import bb

pytestmark = pytest.mark.integration


def test_pub_validates_and_publishes(endpoint: str, node_factory: Callable[..., Node]) -> None:
    got = Collector[m.EyeLidControl](node_factory("listener"), keys.LIDS)
    result = bb("pub", "eyes/lids", '{"eye_id": 2, "top_lid_position": 50, '
                '"bottom_lid_position": 50}', "--connect", endpoint)
    assert result.returncode == 0, result.stderr
    msg = got.wait_for(timeout=10)
    assert msg.eye_id == m.EyeId.BOTH and msg.top_lid_position == 50 and msg.stamp_ns > 0


@pytest.mark.parametrize(
    ("key", "payload", "needle"),
    [
        ("eyes/pupil", '{"dilation_percentage": 150}', "dilation_percentage"),
        ("eyes/pupil", '{"dilation": 15}', "dilation"),
        ("eyes/pupil", "not json", "not valid JSON"),
        ("eyes/nothing", "{}", "not a topic"),
        ("camera/*/image", "{}", "wildcard"),
    ],
)
def test_pub_refuses_bad_messages_naming_the_field(endpoint: str, key: str, payload: str,
                                                   needle: str) -> None:
    result = bb("pub", key, payload, "--connect", endpoint)
    assert result.returncode == 2
    assert needle in result.stderr


def test_pub_warns_when_nobody_listens_and_not_when_someone_does(
        endpoint: str, node_factory: Callable[..., Node]) -> None:
    alone = bb("pub", "eyes/pupil", '{"dilation_percentage": 5}', "--connect", endpoint,
               "--wait", "0.5")
    assert alone.returncode == 0, alone.stderr
    assert "warning: no subscriber matches buddybot/buddy/eyes/pupil" in alone.stderr
    got = Collector[m.PupilControl](node_factory("listener"), keys.PUPIL)
    heard = bb("pub", "eyes/pupil", '{"dilation_percentage": 6}', "--connect", endpoint)
    assert heard.returncode == 0 and "warning" not in heard.stderr, heard.stderr
    got.wait_for(lambda p: p.dilation_percentage == 6, timeout=10)


def test_a_wrong_enum_name_is_a_usage_error_listing_the_names() -> None:
    result = bb("pub", "eyes/expression", '{"action": "EYE_SLEEPING"}',
                "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert result.returncode == 2 and "EYE_SLEEPING" in result.stderr
    assert "EYE_SLEEPY" in result.stderr and "Traceback" not in result.stderr
