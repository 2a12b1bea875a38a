"""Who may operate the robot over Zenoh: the shipped ACL (deploy/zenoh/router.json5).

A real `buddybot router` with the deployment's access control and test-made
certificates, and a real controller and eyes driver on the robot's identity. Setting a
parameter (`params/*`) is the operator laptop's and the robot's; taking a
lease (`leases/acquire`) is the robot's own services' alone (the dashboard
and the Foxglove bridge take the operator lease for a person, from the
robot). A refused query never reaches the arbiter: the caller gets no
reply. Each refusal comes after a positive control through the same router.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import ServiceError
from buddybot.runtime.node import Node
from buddybot.runtime.private_files import secret_file, write_private
from buddybot.tools.testing import Process, retry_until

pytestmark = pytest.mark.integration

REFUSED_HOSTS = ("eye-screen", "radar-board", "camera-host")


def set_centre(node: Node, value: float, timeout: float = 3.0) -> m.ParamReply:
    reply: m.ParamReply = node.call(
        keys.PARAMS, m.ParamRequest(op="set", values={"centre_distance_cm": value}),
        timeout=timeout, node="controller")
    return reply


def get_centre(node: Node) -> float:
    reply: m.ParamReply = node.call(
        keys.PARAMS, m.ParamRequest(op="get", name="centre_distance_cm"), timeout=3,
        node="controller")
    return float(reply.params[0].value)


OPERATOR_SECRET = "the-robots-operator-secret"
"""The robot's operator secret (in the hosts' state folder): the dashboard shows it."""


def acquire(node: Node, timeout: float = 3.0) -> m.LeaseReply:
    reply: m.LeaseReply = node.call(
        keys.LEASE_ACQUIRE, m.LeaseRequest(holder=node.name, instance=node.instance,
                                           resources=["expression"], priority="operator",
                                           credential=OPERATOR_SECRET),
        timeout=timeout)
    return reply


def test_the_acl_lets_the_operator_set_parameters_and_only_the_robot_take_leases(
        host_node: Callable[..., Node], host_process: Callable[..., Process],
        tmp_path: Path) -> None:
    write_private(secret_file("operator", tmp_path / "state"), OPERATOR_SECRET.encode())
    host_process("robot", "run", "controller")
    host_process("robot", "run", "eyes")  # the arbiter: serves leases/acquire
    robot = host_node("robot", "dashboard")
    operator = host_node("operator", "operator-cli")
    # Positive controls: the robot and the operator laptop set a parameter.
    reply = retry_until(lambda: set_centre(robot, 120.0), 60, 0.5,
                        "the controller answering the robot")
    assert reply.error == "" and reply.changed == ["centre_distance_cm"]
    reply = retry_until(lambda: set_centre(operator, 130.0), 30, 0.5,
                        "the controller answering the operator")
    assert reply.error == "" and get_centre(robot) == 130.0
    # The other hosts' parameter requests never reach it.
    for host in REFUSED_HOSTS:
        intruder = host_node(host, f"intruder-{host}")
        with pytest.raises(ServiceError, match="no reply"):
            set_centre(intruder, 999.0, timeout=2)
    assert get_centre(robot) == 130.0
    # Leases: the robot's service takes one; the operator laptop and the others cannot ask.
    def granted() -> m.LeaseReply | None:
        """Asked again while the arbiter has not yet seen the robot node's token."""
        reply = acquire(robot)
        return reply if reply.granted else None

    assert retry_until(granted, 30, 0.5, "a lease for the robot").granted
    for node in [operator, *(host_node(h, f"lessee-{h}") for h in REFUSED_HOSTS)]:
        with pytest.raises(ServiceError, match="no reply"):
            acquire(node, timeout=2)
    # The same path still carries the robot's own requests (its lease was never taken).
    again = acquire(robot)
    assert not again.granted and "held by dashboard" in again.message
