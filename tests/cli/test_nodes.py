"""`buddybot nodes` as a process: the live nodes of one robot or all."""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest

from buddybot.runtime.node import Node
from buddybot.tools.testing import retry_until
from tests.cli.process import bb

pytestmark = pytest.mark.integration


def test_nodes_lists_live_nodes(endpoint: str, node_factory: Callable[..., Node]) -> None:
    node_factory("visible-node")
    node_factory("other-robot-node", robot="r2")
    result = retry_until(
        lambda: (r := bb("nodes", "--connect", endpoint)) and "visible-node" in r.stdout and r,
        30, 0.5)
    assert "other-robot-node" not in result.stdout
    everyone = bb("nodes", "--connect", endpoint, "--all-robots").stdout
    assert "buddy/visible-node" in everyone and "r2/other-robot-node" in everyone


def test_json_is_one_document(endpoint: str, node_factory: Callable[..., Node]) -> None:
    node_factory("visible-node")
    nodes = retry_until(
        lambda: (r := bb("nodes", "--json", "--connect", endpoint)) and r.returncode == 0
        and "visible-node" in r.stdout and json.loads(r.stdout), 30, 0.5, "nodes --json")
    assert nodes["robot"] == "buddy" and len(nodes["nodes"]["visible-node"]) == 1
    empty = bb("nodes", "--json", "--robot", "r2", "--connect", endpoint)
    assert empty.returncode == 1 and json.loads(empty.stdout) == {"robot": "r2", "nodes": {}}
