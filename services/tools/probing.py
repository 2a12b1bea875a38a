"""What the probing verbs (`buddybot echo|hz|pub|call|nodes`) share.

A probe (`ServiceContext.probe`) opens a `Node` with `probe=True`: it talks only through the node's
handles, declares no liveliness token and publishes no diagnostics (a
probe is not a node of the robot). Keys may omit the `buddybot/<robot>/`
prefix and may contain wildcards; messages are decoded with the
catalogue's types.

A probe never hangs and never stays silent about failing: unlike a service
it gives up on the router after its `--timeout` (RouterUnreachable, exit 1,
naming the endpoint and Zenoh's reason), and the verbs say why nothing
arrived (`silence_reason`). Enum fields are typed and shown by name at
these human-facing edges only; the wire keeps integers.
"""

from __future__ import annotations

import time

from buddybot.contract import describe, keyexpr, keys
from buddybot.contract import messages as m
from buddybot.runtime.errors import UsageError
from buddybot.runtime.node import Node


def left(end: float, floor: float = 0.05) -> float:
    """Seconds until `end` (at least `floor`, so a last query can still be sent)."""
    return max(floor, end - time.monotonic())


def catalogue_matches(key: str) -> list[keys.Topic | keys.Service]:
    """Catalogue entries whose keys intersect `key` (an absolute key expression,
    wildcards allowed): empty means the key can never carry a BuddyBot message."""
    if not keyexpr.valid(key):
        return []
    entries: tuple[keys.Topic | keys.Service, ...] = (*keys.TOPICS, *keys.SERVICES)
    return [entry for entry in entries
            if keyexpr.intersects(key, f"{keys.PREFIX_ROOT}/*/{entry.wildcard()}")]


def silence_reason(node: Node, key: str, timeout: float = 2.0) -> str:
    """Why nothing arrived on `key`: an unknown key, a robot with no live node,
    or (the key is known and the robot alive) nobody published on it."""
    if not catalogue_matches(key):
        return f"{key} matches no key of the catalogue (see `buddybot keys`)"
    parts = keys.split_absolute(key)
    robot = parts[0] if parts else node.robot
    if "*" in robot:
        everyone = node.node_instances(all_robots=True, timeout=timeout)
        if not everyone:
            return ("no node of any robot is alive on this router, or its access control "
                    "hides them (see `buddybot nodes --all-robots`)")
        return f"no publisher matches {key} (live nodes: {', '.join(sorted(everyone))})"
    alive = _robot_nodes(node, robot, timeout)
    if not alive:
        return (f"no node of robot {robot!r} is alive on this router, or its access "
                "control hides them (see `buddybot nodes --all-robots`)")
    return f"no publisher matches {key} (live nodes of robot {robot}: {', '.join(alive)})"


def _robot_nodes(node: Node, robot: str, timeout: float) -> list[str]:
    prefix = f"{robot}/"
    return sorted(name[len(prefix):] for name in node.node_instances(all_robots=True,
                                                                     timeout=timeout)
                  if name.startswith(prefix))


def is_latched(key: str) -> bool:
    entry = keys.lookup_absolute(key)
    return isinstance(entry, keys.Topic) and entry.latched


def deadline(seconds: float | None) -> float:
    """A monotonic end time; None or 0 means never."""
    return time.monotonic() + seconds if seconds else float("inf")


def parse_message(topic_or_type: type[m.Message], text: str) -> m.Message:
    """`describe.parse_message` for a verb: a bad message is a usage error (exit 2)."""
    try:
        return describe.parse_message(topic_or_type, text)
    except describe.MessageTextError as exc:
        raise UsageError(str(exc)) from None
